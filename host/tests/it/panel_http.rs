//! `tribo panel` without a browser: who may open the page (loopback, or the access token), what
//! the page's address serves, and the answers to commands when no rig is there.

use crate::support;

use crate::support::TRIBO;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

struct Panel(Child, String);

impl Drop for Panel {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn panel(extra: &[&str], store: &std::path::Path) -> Panel {
    let mut child = Command::new(TRIBO)
        .args(["panel", "--quiet", "--listen", "127.0.0.1:0"])
        .arg("--store")
        .arg(store)
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let url = line
        .split("front panel on ")
        .nth(1)
        .unwrap_or_else(|| panic!("{line:?}"))
        .trim()
        .to_string();
    Panel(child, url)
}

fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .timeout_global(Some(Duration::from_secs(20)))
        .build()
        .into()
}

#[test]
fn beyond_loopback_the_panel_needs_a_token() {
    let out = Command::new(TRIBO)
        .args([
            "panel",
            "--listen",
            "0.0.0.0:0",
            "--port",
            "tcp://127.0.0.1:1",
        ])
        .env_remove("TRIBO_PANEL_TOKEN")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--token") && err.contains("0.0.0.0:0"),
        "{err}"
    );
}

#[test]
fn with_a_token_the_page_and_its_api_need_it() {
    let dir = tempfile::tempdir().unwrap();
    // No rig at this address: the panel serves the page and says the rig is disconnected.
    let p = panel(
        &["--token", "s3cret", "--port", "tcp://127.0.0.1:1"],
        &dir.path().join("runs"),
    );
    assert!(p.1.ends_with("/?token=s3cret"), "{}", p.1);
    let base = p.1.trim_end_matches("?token=s3cret").trim_end_matches('/');
    let a = agent();
    let r = a.get(format!("{base}/")).call().unwrap();
    assert_eq!(r.status(), 401);
    let r = a.get(format!("{base}/api/state")).call().unwrap();
    assert_eq!(r.status(), 401);
    let mut r = a.get(&p.1).call().unwrap();
    assert_eq!(r.status(), 200);
    let cookie = r
        .headers()
        .get("set-cookie")
        .and_then(|v| v.to_str().ok())
        .unwrap()
        .split(';')
        .next()
        .unwrap()
        .to_string();
    assert_eq!(cookie, "tribo_panel=s3cret");
    let page = r.body_mut().read_to_string().unwrap();
    // Its script comes from the program itself: no other origin is named.
    assert!(page.contains("<script src=\"panel.js\">"), "{page}");
    assert!(!page.contains("http://") && !page.contains("https://"));
    let mut r = a
        .get(format!("{base}/panel.js"))
        .header("Cookie", &cookie)
        .call()
        .unwrap();
    assert_eq!(r.status(), 200);
    assert!(r
        .body_mut()
        .read_to_string()
        .unwrap()
        .contains("EventSource"));
    // No rig: the state says so, and why.
    let mut state = serde_json::Value::Null;
    for _ in 0..50 {
        state = a
            .get(format!("{base}/api/state"))
            .header("Cookie", &cookie)
            .call()
            .unwrap()
            .body_mut()
            .read_json()
            .unwrap();
        if state["link_error"]
            .as_str()
            .is_some_and(|e| e.contains("127.0.0.1:1"))
        {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(state["connected"], false, "{state}");
    assert!(
        state["link_error"]
            .as_str()
            .unwrap()
            .contains("127.0.0.1:1"),
        "{state}"
    );
    // A command needs the page's id (a custom header: no other site's page can send one).
    let r = a
        .post(format!("{base}/api/arm"))
        .header("Cookie", &cookie)
        .send("{}")
        .unwrap();
    assert_eq!(r.status(), 400);
    // Safe from a page with no rig there: said, not pretended.
    let mut r = a
        .post(format!("{base}/api/safe"))
        .header("Cookie", &cookie)
        .header("X-Panel-Client", "t1")
        .send("{}")
        .unwrap();
    assert_eq!(r.status(), 503);
    let v: serde_json::Value = r.body_mut().read_json().unwrap();
    assert!(
        v["text"].as_str().unwrap().contains("no rig is connected"),
        "{v}"
    );
    // The first page to claim control gets it; a command is then refused because no rig is there.
    let r = a
        .post(format!("{base}/api/claim"))
        .header("Cookie", &cookie)
        .header("X-Panel-Client", "t1")
        .send("{}")
        .unwrap();
    assert_eq!(r.status(), 200);
    let r = a
        .post(format!("{base}/api/claim"))
        .header("Cookie", &cookie)
        .header("X-Panel-Client", "t2")
        .send("{}")
        .unwrap();
    assert_eq!(r.status(), 409);
    let mut r = a
        .post(format!("{base}/api/arm"))
        .header("Cookie", &cookie)
        .header("X-Panel-Client", "t1")
        .send("{}")
        .unwrap();
    let v: serde_json::Value = r.body_mut().read_json().unwrap();
    assert_eq!(r.status(), 409, "{v}");
    assert!(
        v["text"].as_str().unwrap().contains("no rig is connected"),
        "{v}"
    );
}

/// A raw HTTP/1.1 request to `addr` with exactly these headers (a forged `Host` cannot be sent
/// with an HTTP client that derives it from the URL): the status code and the body.
fn raw(
    addr: &str,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &str,
) -> (u16, String) {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let mut req = format!("{method} {path} HTTP/1.1\r\nConnection: close\r\n");
    for (k, v) in headers {
        req.push_str(&format!("{k}: {v}\r\n"));
    }
    req.push_str(&format!("Content-Length: {}\r\n\r\n{body}", body.len()));
    s.write_all(req.as_bytes()).unwrap();
    let mut out = String::new();
    let _ = s.read_to_string(&mut out);
    let status = out
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("no status in {out:?}"));
    (status, out)
}

/// The panel answers only to itself: a request whose `Host` is another name (a page whose DNS name
/// was rebound to 127.0.0.1) or whose `Origin` is another site is refused before anything else,
/// whatever it carries; on loopback every request but the page carries the token too (a command
/// with the page's id and no token was obeyed: `curl -H "Host: attacker.example:PORT" -H
/// "X-Panel-Client: abc" -d '{…}' …/api/heater` answered `{"ok":true,…}`).
#[test]
fn the_panel_refuses_a_forged_host_or_origin_and_a_command_without_its_token() {
    let dir = tempfile::tempdir().unwrap();
    let p = panel(&["--port", "tcp://127.0.0.1:1"], &dir.path().join("runs"));
    // The printed address carries the token made at start, on loopback too.
    let (base, token) =
        p.1.split_once("/?token=")
            .unwrap_or_else(|| panic!("{}", p.1));
    assert!(token.len() >= 32, "{token}");
    let addr = base.trim_start_matches("http://").to_string();
    let port = addr.rsplit_once(':').unwrap().1.to_string();
    let heat = r#"{"setpoint_c":35,"ramp_c_per_min":10}"#;
    let cookie = format!("tribo_panel={token}");
    let forged_host = format!("attacker.example:{port}");
    for (what, headers) in [
        (
            "a rebound name",
            vec![
                ("Host", forged_host.as_str()),
                ("X-Panel-Client", "abc"),
                ("Cookie", cookie.as_str()),
            ],
        ),
        (
            "another site's page",
            vec![
                ("Host", addr.as_str()),
                ("Origin", "http://attacker.example"),
                ("X-Panel-Client", "abc"),
                ("Cookie", cookie.as_str()),
            ],
        ),
        (
            "the right port on another name",
            vec![
                ("Host", "evil.localhost.example"),
                ("X-Panel-Client", "abc"),
            ],
        ),
    ] {
        for path in ["/api/heater", "/api/safe"] {
            let (status, body) = raw(&addr, "POST", path, &headers, heat);
            assert_eq!(status, 403, "{what} {path}: {body}");
            assert!(
                body.contains("refused") && !body.contains("\"ok\":true"),
                "{body}"
            );
        }
        let (status, _) = raw(&addr, "GET", "/api/state", &headers, "");
        assert_eq!(status, 403, "{what}: the state is not read either");
        let (status, _) = raw(&addr, "GET", "/", &headers, "");
        assert_eq!(status, 403, "{what}: nor the page (and the cookie it sets)");
    }
    // Its own address, without the token: the page is served (and sets the cookie), nothing else.
    let own = [("Host", addr.as_str()), ("X-Panel-Client", "abc")];
    let (status, page) = raw(&addr, "GET", "/", &own, "");
    assert_eq!(status, 200, "{page}");
    assert!(page.contains(&format!("tribo_panel={token}")), "{page}");
    let (status, body) = raw(&addr, "POST", "/api/heater", &own, heat);
    assert_eq!(status, 401, "a command without the token: {body}");
    let (status, _) = raw(&addr, "GET", "/api/state", &own, "");
    assert_eq!(status, 401);
    // `localhost` and the page's own origin are the panel's.
    let local = format!("localhost:{port}");
    let origin = format!("http://{addr}");
    let ok = [
        ("Host", local.as_str()),
        ("Origin", origin.as_str()),
        ("X-Panel-Client", "abc"),
        ("Cookie", cookie.as_str()),
    ];
    let (status, body) = raw(&addr, "POST", "/api/claim", &ok, "{}");
    assert_eq!(status, 200, "{body}");
    let (status, body) = raw(&addr, "GET", "/api/state", &ok, "");
    assert_eq!(status, 200, "{body}");
}

/// A release while the plate is still settling is refused until the page confirms it (`tribo
/// run` waits for the plate; the panel released at once).
#[test]
fn a_release_while_the_plate_settles_needs_a_confirmation() {
    let dir = tempfile::tempdir().unwrap();
    let rig = support::RigProcess::start(1.0);
    let p = panel(&["--port", &rig.addr], &dir.path().join("runs"));
    let (base, token) = p.1.split_once("/?token=").unwrap();
    let a = agent();
    let post = |name: &str, body: &str| -> (u16, serde_json::Value) {
        let mut r = a
            .post(format!("{base}/api/{name}"))
            .header("X-Panel-Token", token)
            .header("X-Panel-Client", "t1")
            .send(body)
            .unwrap();
        (r.status().as_u16(), r.body_mut().read_json().unwrap())
    };
    // Wait for the rig, take control, heat.
    let mut connected = false;
    for _ in 0..100 {
        let v: serde_json::Value = a
            .get(format!("{base}/api/state"))
            .header("X-Panel-Token", token)
            .call()
            .unwrap()
            .body_mut()
            .read_json()
            .unwrap();
        if v["connected"] == true {
            connected = true;
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(connected, "the panel never reached the rig");
    assert_eq!(post("claim", "{}").0, 200);
    let (s, v) = post("heater", r#"{"setpoint_c":40,"ramp_c_per_min":10}"#);
    assert_eq!(s, 200, "{v}");
    let mut settling = serde_json::Value::Null;
    for _ in 0..50 {
        let (s, v) = post("release", "{}");
        if v["confirm"] == true {
            assert_eq!(s, 409, "{v}");
            settling = v;
            break;
        }
        // The panel has not seen the setpoint in the rig's status yet.
        std::thread::sleep(Duration::from_millis(100));
    }
    let text = settling["text"]
        .as_str()
        .unwrap_or_else(|| panic!("never asked: {settling}"));
    assert!(
        text.contains("still settling") && text.contains("40.0 °C"),
        "{text}"
    );
    assert_eq!(settling["ok"], false);
    // Confirmed, it goes to the rig (which refuses it here: nothing is armed).
    let (_, v) = post("release", r#"{"confirm":true}"#);
    assert!(v.get("confirm").is_none(), "{v}");
    let _ = post("safe", "{}");
}

/// A damaged run of the store is not dropped from the panel's campaign grid without a word: the
/// grid names it and how to repair it (as `tribo table` does).
#[test]
fn the_grid_names_a_damaged_run_it_leaves_out() {
    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("runs");
    let rig = support::RigProcess::start(f64::INFINITY);
    for _ in 0..2 {
        let o = Command::new(TRIBO)
            .args(["run", "-q", "--load", "0.3", "--port", &rig.addr, "--store"])
            .arg(&store)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let mut runs: Vec<std::path::PathBuf> = std::fs::read_dir(&store)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("meta.toml").is_file())
        .collect();
    runs.sort();
    let log = runs[0].join("frames.log");
    let mut b = std::fs::read(&log).unwrap();
    let at = b.len() / 3;
    b[at] ^= 0x40;
    std::fs::write(&log, b).unwrap();
    let p = panel(&["--port", "tcp://127.0.0.1:1"], &store);
    let (base, token) = p.1.split_once("/?token=").unwrap();
    let v: serde_json::Value = agent()
        .get(format!("{base}/api/state"))
        .header("X-Panel-Token", token)
        .call()
        .unwrap()
        .body_mut()
        .read_json()
        .unwrap();
    let grid = &v["grid"];
    assert_eq!(grid["cells"][0][0]["n"], 1, "{grid}");
    let left = grid["left_out"].as_array().unwrap();
    assert_eq!(left.len(), 1, "{grid}");
    let name = runs[0].file_name().unwrap().to_str().unwrap();
    assert_eq!(left[0]["run"], name, "{grid}");
    assert!(
        left[0]["why"]
            .as_str()
            .unwrap()
            .contains("tribo pull --salvage"),
        "{grid}"
    );
}

/// `--listen NAME:PORT`: the panel listens where the name resolves and answers to that name (and
/// its address); another name is refused.
#[test]
fn a_name_given_with_listen_is_answered_to() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(TRIBO)
        .args([
            "panel",
            "--quiet",
            "--listen",
            "localhost:0",
            "--port",
            "tcp://127.0.0.1:1",
        ])
        .arg("--store")
        .arg(dir.path().join("runs"))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let p = Panel(child, line);
    let url =
        p.1.split("front panel on ")
            .nth(1)
            .unwrap()
            .trim()
            .to_string();
    assert!(url.starts_with("http://localhost:"), "{url}");
    let (base, token) = url.split_once("/?token=").unwrap();
    let port = base.rsplit_once(':').unwrap().1;
    let addr = format!("127.0.0.1:{port}");
    let named = format!("localhost:{port}");
    let other = format!("other.example:{port}");
    let cookie = format!("tribo_panel={token}");
    let (status, body) = raw(
        &addr,
        "GET",
        "/api/state",
        &[("Host", &named), ("Cookie", &cookie)],
        "",
    );
    assert_eq!(status, 200, "{body}");
    let (status, _) = raw(
        &addr,
        "GET",
        "/api/state",
        &[("Host", &other), ("Cookie", &cookie)],
        "",
    );
    assert_eq!(status, 403);
}
