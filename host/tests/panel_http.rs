//! `tribo panel` without a browser: who may open the page (loopback, or the access token), what
//! the page's address serves, and the answers to commands when no rig is there.

mod support;

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::Duration;
use support::TRIBO;

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
