//! `tribo sync`, `runs`/`table --catalog` and `pull --from-catalog` as a lab uses them: real
//! `tribo` processes against a real PostgreSQL server (started in a temporary folder), several
//! PCs at once, one killed midway.

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};
use tribo_testkit::{synthetic_store, PgServer, ADMIN, ADMIN_PASSWORD};

use crate::support;
use crate::support::TRIBO;

fn tribo(args: &[&str], password: &str) -> Command {
    let mut c = support::command(args);
    c.env("PGPASSWORD", password).env_remove("PGPASSFILE");
    c
}

fn ok(o: Output) -> String {
    assert!(
        o.status.success(),
        "status {:?}\nstdout: {}\nstderr: {}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn store_of(dir: &Path, serial: &str, n: u32) {
    synthetic_store(
        dir,
        serial,
        1,
        n,
        |_| 0.01,
        |i, m| {
            m.campaign = Some("dlc-60".into());
            m.temp_setpoint_c = Some(if i % 2 == 0 { 60.0 } else { 25.0 });
            m.load_n = 0.2;
        },
    );
}

#[test]
fn pcs_sync_at_once_one_is_killed_and_the_lab_reads_across_rigs() {
    if PgServer::skip() {
        return;
    }
    let pg = PgServer::start();
    let admin = pg.url(ADMIN, "lab");
    // A password on the command line is refused, and not echoed.
    let o = tribo(
        &[
            "runs",
            "--catalog",
            &pg.url(&format!("{ADMIN}:hunter2"), "lab"),
        ],
        "",
    )
    .output()
    .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    // A URL that cannot be right is a usage error (status 2), as any wrong command line.
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("PGPASSWORD") && !err.contains("hunter2"),
        "{err}"
    );

    // The owner's first sync creates the tables; then a writer role, as the README says.
    let empty = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(empty.path().join("runs")).unwrap();
    ok(tribo(
        &[
            "sync",
            "--store",
            &empty.path().join("runs").to_string_lossy(),
            "--catalog",
            &admin,
        ],
        ADMIN_PASSWORD,
    )
    .output()
    .unwrap());
    pg.psql(
        "lab",
        "CREATE ROLE writer LOGIN PASSWORD 'wpw'; GRANT SELECT, INSERT, UPDATE ON tribo_runs TO writer; \
         GRANT SELECT ON tribo_schema TO writer",
    );
    let writer = pg.url("writer", "lab");

    // Three PCs, and a fourth process syncing the first PC's store again, all at once.
    let stores: Vec<_> = (0..3).map(|_| tempfile::tempdir().unwrap()).collect();
    let serials = ["00000000000000a1", "00000000000000b2", "00000000000000c3"];
    for (s, serial) in stores.iter().zip(serials) {
        store_of(s.path(), serial, 40);
    }
    let mut kids: Vec<_> = stores
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let store = s.path().to_string_lossy().into_owned();
            tribo(
                &[
                    "-q",
                    "sync",
                    "--store",
                    &store,
                    "--catalog",
                    &writer,
                    "--pc",
                    &format!("pc{i}"),
                    "--batch",
                    "7",
                ],
                "wpw",
            )
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
        })
        .collect();
    let store0 = stores[0].path().to_string_lossy().into_owned();
    kids.push(
        tribo(
            &[
                "-q",
                "sync",
                "--store",
                &store0,
                "--catalog",
                &writer,
                "--pc",
                "pc0",
                "--batch",
                "3",
            ],
            "wpw",
        )
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap(),
    );
    for k in kids {
        ok(k.wait_with_output().unwrap());
    }
    assert_eq!(pg.run_count(), 120);
    let again = ok(tribo(
        &[
            "sync",
            "--store",
            &store0,
            "--catalog",
            &writer,
            "--pc",
            "pc0",
            "--json",
        ],
        "wpw",
    )
    .output()
    .unwrap());
    let j: serde_json::Value = serde_json::from_str(&again).unwrap();
    assert_eq!(
        (j["unchanged"].as_u64(), j["inserted"].as_u64()),
        (Some(40), Some(0)),
        "{j}"
    );

    // A PC killed mid-sync leaves whole batches; the next sync sends the rest.
    let big = tempfile::tempdir().unwrap();
    store_of(big.path(), "00000000000000d4", 300);
    let bigs = big.path().to_string_lossy().into_owned();
    let mut k = tribo(
        &[
            "-q",
            "sync",
            "--store",
            &bigs,
            "--catalog",
            &writer,
            "--pc",
            "pc3",
            "--batch",
            "10",
        ],
        "wpw",
    )
    .stdout(Stdio::null())
    .stderr(Stdio::null())
    .spawn()
    .unwrap();
    let t = Instant::now();
    while pg.run_count() == 120 && t.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(5));
    }
    k.kill().unwrap();
    k.wait().unwrap();
    let sent = pg.run_count() - 120;
    assert!(
        sent > 0 && sent.is_multiple_of(10),
        "whole batches only: {sent}"
    );
    let j: serde_json::Value = serde_json::from_str(&ok(tribo(
        &[
            "sync",
            "--store",
            &bigs,
            "--catalog",
            &writer,
            "--pc",
            "pc3",
            "--json",
        ],
        "wpw",
    )
    .output()
    .unwrap()))
    .unwrap();
    assert_eq!(
        j["inserted"].as_u64().unwrap() + j["unchanged"].as_u64().unwrap(),
        300,
        "{j}"
    );
    assert_eq!(pg.run_count(), 420);

    // Reading the lab: across rigs, one rig, a campaign table.
    let runs: serde_json::Value = serde_json::from_str(&ok(tribo(
        &["runs", "--catalog", &writer, "--temp", "60", "--json"],
        "wpw",
    )
    .output()
    .unwrap()))
    .unwrap();
    assert_eq!(runs["runs"].as_array().unwrap().len(), 210);
    let one: serde_json::Value = serde_json::from_str(&ok(tribo(
        &["runs", "--catalog", &writer, "--rig", serials[1], "--json"],
        "wpw",
    )
    .output()
    .unwrap()))
    .unwrap();
    let one = one["runs"].as_array().unwrap();
    assert_eq!(one.len(), 40);
    assert!(one
        .iter()
        .all(|r| r["rig"] == serials[1] && r["pc"] == "pc1"));
    let table: serde_json::Value = serde_json::from_str(&ok(tribo(
        &[
            "table",
            "--catalog",
            &writer,
            "--campaign",
            "dlc-60",
            "--value",
            "onboard-mu0",
            "--json",
        ],
        "wpw",
    )
    .output()
    .unwrap()))
    .unwrap();
    let n: u64 = table["cells"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|r| r.as_array().unwrap())
        .map(|c| c["n"].as_u64().unwrap())
        .sum();
    assert_eq!(n, 420);
    // A campaign's report from one rig's runs in the lab.
    let rep = tempfile::tempdir().unwrap();
    let out = ok(tribo(
        &[
            "report",
            "dlc-60",
            "--catalog",
            &writer,
            "--rig",
            serials[2],
            "--no-png",
            "-o",
            &rep.path().to_string_lossy(),
        ],
        "wpw",
    )
    .output()
    .unwrap());
    let html = std::fs::read_to_string(rep.path().join("report.html")).unwrap();
    assert!(
        out.contains("report.html") && html.contains("dlc-60"),
        "{out}"
    );
    let text = ok(tribo(&["runs", "--catalog", &writer], "wpw")
        .output()
        .unwrap());
    assert!(text.contains("420 runs from the lab catalog"), "{text}");

    // A reader may read, not write: a clear error, nothing written.
    pg.psql("lab", "CREATE ROLE reader LOGIN PASSWORD 'rpw'; GRANT SELECT ON tribo_runs, tribo_schema TO reader");
    let fresh = tempfile::tempdir().unwrap();
    store_of(fresh.path(), "00000000000000e5", 2);
    let o = tribo(
        &[
            "sync",
            "--store",
            &fresh.path().to_string_lossy(),
            "--catalog",
            &pg.url("reader", "lab"),
        ],
        "rpw",
    )
    .output()
    .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("may not") && err.contains("INSERT and UPDATE"),
        "{err}"
    );
    assert_eq!(pg.run_count(), 420);
}

#[test]
fn pull_from_catalog_fetches_a_run_from_a_shared_folder_and_checks_its_hash() {
    if PgServer::skip() {
        return;
    }
    let pg = PgServer::start();
    let admin = pg.url(ADMIN, "lab");
    let shared = tempfile::tempdir().unwrap();
    store_of(shared.path(), "00000000000000a1", 2);
    let s = shared.path().to_string_lossy().into_owned();
    ok(tribo(
        &[
            "sync",
            "--store",
            &s,
            "--catalog",
            &admin,
            "--pc",
            "rig-pc",
            "--shared-as",
            &s,
        ],
        ADMIN_PASSWORD,
    )
    .output()
    .unwrap());
    let mine = tempfile::tempdir().unwrap();
    let m = mine.path().join("runs");
    let ms = m.to_string_lossy().into_owned();
    let out = ok(tribo(
        &[
            "pull",
            "--store",
            &ms,
            "--catalog",
            &admin,
            "--from-catalog",
            "00000000000000a1/2",
        ],
        ADMIN_PASSWORD,
    )
    .output()
    .unwrap());
    assert!(
        out.contains("from PC \"rig-pc\"") && out.contains("complete"),
        "{out}"
    );
    let listed = ok(tribo(&["runs", "--store", &ms, "--json"], "")
        .output()
        .unwrap());
    let j: serde_json::Value = serde_json::from_str(&listed).unwrap();
    assert_eq!(j["runs"].as_array().unwrap().len(), 1, "{j}");
    assert_eq!(j["runs"][0]["status"], "complete");
    // Again: already here.
    let out = ok(tribo(
        &[
            "pull",
            "--store",
            &ms,
            "--catalog",
            &admin,
            "--from-catalog",
            "00000000000000a1/2",
        ],
        ADMIN_PASSWORD,
    )
    .output()
    .unwrap());
    assert!(out.contains("already here"), "{out}");
    // A log changed since its PC synced is refused.
    for dir in tribo_store::run::list_run_dirs(shared.path()).unwrap() {
        let mut f = std::fs::OpenOptions::new()
            .append(true)
            .open(dir.join("frames.log"))
            .unwrap();
        std::io::Write::write_all(&mut f, b"x").unwrap();
    }
    let other = mine.path().join("other");
    let o = tribo(
        &[
            "pull",
            "--store",
            &other.to_string_lossy(),
            "--catalog",
            &admin,
            "--from-catalog",
            "00000000000000a1/1",
        ],
        ADMIN_PASSWORD,
    )
    .output()
    .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("not the one the lab catalog holds"),
        "{err}"
    );
    assert!(
        !other.join("x").exists()
            && tribo_store::run::list_run_dirs(&other).map_or(0, |d| d.len()) == 0
    );
    // A log on a folder this PC cannot reach: says where it is.
    ok(tribo(
        &[
            "sync",
            "--store",
            &s,
            "--catalog",
            &admin,
            "--pc",
            "rig-pc",
            "--shared-as",
            "/nowhere/lab",
        ],
        ADMIN_PASSWORD,
    )
    .output()
    .unwrap());
    let o = tribo(
        &[
            "pull",
            "--store",
            &other.to_string_lossy(),
            "--catalog",
            &admin,
            "--from-catalog",
            "00000000000000a1/2",
        ],
        ADMIN_PASSWORD,
    )
    .output()
    .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("cannot reach") && err.contains("/nowhere/lab"),
        "{err}"
    );
}

/// `tribo campaign --catalog URL` on two rigs, one PC each: each PC's campaign syncs its runs and
/// prints the lab's table, so the second one sees the runs of both rigs in one cell. With the
/// server out of reach the campaign's runs are kept and its own table shown, and it says to run
/// `tribo sync` later (exit 1: what was asked, the lab's table, was not done).
#[test]
fn a_campaign_on_two_rigs_ends_with_the_lab_s_table() {
    if PgServer::skip() {
        return;
    }
    let pg = PgServer::start();
    let admin = pg.url(ADMIN, "lab");
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("plan.toml");
    std::fs::write(
        &plan,
        "name = \"cross\"\nloads_n = [0.3]\nrepeats = 2\nmax_duration_s = 8.0\n",
    )
    .unwrap();
    let plan = plan.to_string_lossy().into_owned();
    let campaign = |rig: &support::RigProcess, store: &str, catalog: &str| {
        tribo(
            &[
                "campaign",
                &plan,
                "--no-prompt",
                "--port",
                &rig.addr,
                "--store",
                store,
                "--catalog",
                catalog,
            ],
            ADMIN_PASSWORD,
        )
        .output()
        .unwrap()
    };
    let cell = |out: &str| -> String {
        out.lines()
            .skip_while(|l| !l.starts_with("μ0"))
            .find(|l| l.starts_with("heater off"))
            .unwrap_or_else(|| panic!("no heater-off row in\n{out}"))
            .to_string()
    };
    let (r1, r2) = (
        support::RigProcess::start(20.0),
        support::RigProcess::start(20.0),
    );
    assert_ne!(r1.info().serial, r2.info().serial);
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let out = ok(campaign(&r1, &a.to_string_lossy(), &admin));
    assert!(out.contains("every rig in the lab catalog"), "{out}");
    assert!(cell(&out).ends_with("(2)"), "{out}");
    let out = ok(campaign(&r2, &b.to_string_lossy(), &admin));
    assert!(
        cell(&out).ends_with("(4)"),
        "both rigs' runs in one cell\n{out}"
    );
    let listed = ok(tribo(
        &["runs", "--catalog", &admin, "--campaign", "cross", "--json"],
        ADMIN_PASSWORD,
    )
    .output()
    .unwrap());
    let j: serde_json::Value = serde_json::from_str(&listed).unwrap();
    let serials: std::collections::BTreeSet<&str> = j["runs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["serial"].as_str().unwrap())
        .collect();
    assert_eq!(serials.len(), 2, "{j}");
    // `table` and `report` take the days the runs were taken in, as `runs` does.
    let table = |period: &[&str]| {
        let mut a = vec![
            "table",
            "--catalog",
            &admin,
            "--campaign",
            "cross",
            "--json",
        ];
        a.extend_from_slice(period);
        let j: serde_json::Value =
            serde_json::from_str(&ok(tribo(&a, ADMIN_PASSWORD).output().unwrap())).unwrap();
        j["cells"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|r| {
                r.as_array()
                    .unwrap()
                    .iter()
                    .map(|c| c["n"].as_u64().unwrap_or(0))
            })
            .sum::<u64>()
    };
    assert_eq!(table(&["--since", "2000-01-01"]), 4);
    assert_eq!(table(&["--until", "2000-01-01"]), 0);
    let report = dir.path().join("report");
    let o = tribo(
        &[
            "report",
            "cross",
            "--catalog",
            &admin,
            "--until",
            "2000-01-01",
            "--no-png",
            "-o",
            &report.to_string_lossy(),
        ],
        ADMIN_PASSWORD,
    )
    .output()
    .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no run of campaign"));

    // The server out of reach: a finished campaign shows its own table and says what to do.
    let gone = "postgres://tribo@127.0.0.1:1/lab";
    let o = campaign(&r1, &a.to_string_lossy(), gone);
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert_eq!(o.status.code(), Some(1), "{out}\n{err}");
    assert!(
        out.contains("this PC's runs") && cell(&out).ends_with("(2)"),
        "{out}"
    );
    assert!(
        err.contains("tribo sync") && err.contains("stored"),
        "{err}"
    );
}

/// What a PC is told when it cannot use the lab catalog says why and what to do: no password
/// found (a password file readable by others is named with `chmod 600`; none at all names where
/// to put it), and a role that may only read is not told it "needs INSERT and UPDATE" to read.
/// (Both read "the lab catalog … answered with an error" and a writer's rights.)
#[test]
fn a_missing_password_a_read_only_role_and_a_damaged_run_are_told_what_to_do() {
    if PgServer::skip() {
        return;
    }
    let pg = PgServer::start();
    let empty = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(empty.path().join("runs")).unwrap();
    let store = empty.path().join("runs").to_string_lossy().into_owned();
    ok(tribo(
        &[
            "sync",
            "--store",
            &store,
            "--catalog",
            &pg.url(ADMIN, "lab"),
        ],
        ADMIN_PASSWORD,
    )
    .output()
    .unwrap());
    pg.psql(
        "lab",
        "CREATE ROLE nosy LOGIN PASSWORD 'npw'; CREATE ROLE reader LOGIN PASSWORD 'rpw'; \
         GRANT SELECT ON tribo_schema TO reader, nosy; GRANT SELECT ON tribo_runs TO reader",
    );
    // No password anywhere; then one in a password file the group may read.
    let home = tempfile::tempdir().unwrap();
    let runs = |pgpass: Option<u32>| {
        if let Some(mode) = pgpass {
            use std::os::unix::fs::PermissionsExt;
            let f = home.path().join(".pgpass");
            std::fs::write(&f, "*:*:*:reader:rpw\n").unwrap();
            std::fs::set_permissions(&f, std::fs::Permissions::from_mode(mode)).unwrap();
        }
        let o = Command::new(TRIBO)
            .args(["runs", "--catalog", &pg.url("reader", "lab")])
            .env_remove("PGPASSWORD")
            .env_remove("PGPASSFILE")
            .env_remove("TRIBO_CATALOG")
            .env("HOME", home.path())
            .stdin(Stdio::null())
            .output()
            .unwrap();
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let (status, err) = runs(None);
    assert_eq!(status, Some(1), "{err}");
    assert!(
        err.contains("none was found") && err.contains("PGPASSWORD") && err.contains("chmod 600"),
        "{err}"
    );
    assert!(!err.contains("answered with an error"), "{err}");
    let (status, err) = runs(Some(0o644));
    assert_eq!(status, Some(1), "{err}");
    assert!(err.contains("0644") && err.contains("chmod 600"), "{err}");
    let (status, err) = runs(Some(0o600));
    assert_eq!(status, Some(0), "{err}");
    // A damaged run of this PC is not synced, said with how to repair it, and the sync is not
    // whole: status 3 (it was 0).
    let pc = tempfile::tempdir().unwrap();
    store_of(pc.path(), "00000000000000d4", 2);
    let mut runs: Vec<_> = std::fs::read_dir(pc.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("frames.log").is_file())
        .collect();
    runs.sort();
    let log = runs[0].join("frames.log");
    let mut b = std::fs::read(&log).unwrap();
    let at = b.len() / 2;
    b[at] ^= 0x40;
    std::fs::write(&log, b).unwrap();
    let o = tribo(
        &[
            "sync",
            "--store",
            &pc.path().to_string_lossy(),
            "--catalog",
            &pg.url(ADMIN, "lab"),
        ],
        ADMIN_PASSWORD,
    )
    .output()
    .unwrap();
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert_eq!(o.status.code(), Some(3), "{out}{err}");
    let name = runs[0].file_name().unwrap().to_string_lossy().into_owned();
    assert!(
        out.contains("not synced") && out.contains(&name) && out.contains("--salvage"),
        "{out}"
    );
    assert!(
        err.contains("incomplete:") && err.contains("1 run of this PC not synced"),
        "{err}"
    );
    // `tribo export --catalog URL`: the lab catalog as one table, as `--catalog URL` reads it
    // everywhere else (it was a switch for this PC's store only); `--catalog` alone: this PC's,
    // the damaged run named and the export not whole (3).
    let out = pc.path().join("lab.json");
    let o = tribo(
        &[
            "export",
            "--catalog",
            &pg.url(ADMIN, "lab"),
            "--format",
            "json",
            "-o",
            &out.to_string_lossy(),
        ],
        ADMIN_PASSWORD,
    )
    .output()
    .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(v["runs"].as_array().unwrap().len(), pg.run_count(), "{v}");
    assert_eq!(pg.run_count(), 1);
    let o = tribo(
        &[
            "export",
            "--catalog",
            "--store",
            &pc.path().to_string_lossy(),
            "--format",
            "json",
            "-o",
            &out.to_string_lossy(),
        ],
        "",
    )
    .output()
    .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{err}");
    assert!(err.contains(&name) && err.contains("--salvage"), "{err}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(v["runs"].as_array().unwrap().len(), 1, "{v}");
    // A role that may not read tribo_runs, reading: told it needs SELECT, not a writer's rights.
    let o = tribo(&["runs", "--catalog", &pg.url("nosy", "lab")], "npw")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("SELECT") && !err.contains("INSERT and UPDATE"),
        "{err}"
    );
}
