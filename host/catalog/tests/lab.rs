//! The lab catalog against a real PostgreSQL server (started per test in a temporary folder):
//! schema, sync, reading across rigs, and the faults of a lab's network.

use std::path::Path;
use std::sync::mpsc;
use std::time::Duration;
use tribo_catalog::{sync, AnyCatalog, LabCatalog, SyncOptions};
use tribo_store::catalog::{Axis, Bin, Value};
use tribo_store::Filter;
use tribo_testkit::{synthetic_run, synthetic_store, PgServer};

fn opts(pc: &str) -> SyncOptions {
    SyncOptions {
        pc: pc.into(),
        shared_as: None,
        batch: 50,
        wait: Duration::from_secs(20),
    }
}

/// A store of `n` runs of rig `serial` (run numbers from `first`), campaign `c`, loads 0.2/0.4 N,
/// temperatures 25/60 °C.
fn store_of(dir: &Path, serial: &str, first: u32, n: u32) {
    synthetic_store(
        dir,
        serial,
        first,
        n,
        |i| 0.01 + 0.001 * i as f32,
        |i, m| {
            m.campaign = Some("c".into());
            m.repeat = Some(i / 4 + 1);
            m.load_n = if i % 2 == 0 { 0.2 } else { 0.4 };
            m.temp_setpoint_c = Some(if (i / 2) % 2 == 0 { 25.0 } else { 60.0 });
            m.label = Some(format!("DLC {i}"));
        },
    );
}

#[test]
fn sync_is_idempotent_reads_across_rigs_and_follows_a_log_that_grows() {
    if PgServer::skip() {
        return;
    }
    let pg = PgServer::start();
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    store_of(a.path(), "00000000000000a1", 1, 12);
    store_of(b.path(), "00000000000000b2", 1, 8);
    let url = pg.admin();
    let r = sync(a.path(), &url, &opts("pc-a"), &mut |_, _| {}).unwrap();
    assert_eq!(
        (r.local, r.pushed.inserted, r.unchanged),
        (12, 12, 0),
        "{r:?}"
    );
    let r = sync(b.path(), &url, &opts("pc-b"), &mut |_, _| {}).unwrap();
    assert_eq!(r.pushed.inserted, 8, "{r:?}");
    // Again: nothing sent, nothing changed.
    let r = sync(a.path(), &url, &opts("pc-a"), &mut |_, _| {}).unwrap();
    assert_eq!((r.unchanged, r.pushed), (12, Default::default()), "{r:?}");
    assert_eq!(pg.run_count(), 20);

    let lab = LabCatalog::connect(&url).unwrap();
    let all = lab.lab_runs(&Filter::default()).unwrap();
    assert_eq!(all.len(), 20);
    // The rows say what the local catalog says, and where the log is, with its hash.
    let local = tribo_store::RunCatalog::open(a.path())
        .unwrap()
        .list(&Filter::default())
        .unwrap();
    for l in &local {
        let r = all
            .iter()
            .find(|r| r.run.row.id == l.id && r.run.pc == "pc-a")
            .unwrap();
        let mut row = r.run.row.clone();
        row.path = l.path.clone();
        assert_eq!(&row, l);
        assert_eq!(
            Path::new(&r.run.log_dir),
            std::path::absolute(&l.path).unwrap()
        );
        assert_eq!(
            r.run.log_sha256,
            tribo_catalog::sync::file_sha256(&l.path.join("frames.log")).unwrap()
        );
        assert_eq!(r.run.onboard_mu0_se, Some(0.0001f32 as f64));
    }
    // Across rigs, and one rig.
    let hot = Filter {
        temp_min: Some(59.5),
        temp_max: Some(60.5),
        label: Some("DLC".into()),
        ..Default::default()
    };
    assert_eq!(lab.runs(&hot).unwrap().len(), 6 + 4);
    let one = Filter {
        rig: Some("00000000000000b2".into()),
        ..Default::default()
    };
    assert_eq!(lab.runs(&one).unwrap().len(), 8);
    let t = lab
        .table(
            Axis::Temp,
            Axis::Load,
            Value::OnboardMu0,
            &Filter::default(),
        )
        .unwrap();
    assert_eq!((t.rows.len(), t.cols.len()), (2, 2));
    let n: usize = t.cells.iter().flatten().map(|c| c.unwrap().n).sum();
    assert_eq!(n, 20);
    // The same table as the local catalogs' rows put together.
    let mut rows = local.clone();
    rows.extend(
        tribo_store::RunCatalog::open(b.path())
            .unwrap()
            .list(&Filter::default())
            .unwrap(),
    );
    rows.iter_mut().for_each(|r| r.status = "complete".into());
    let expect = tribo_store::catalog::tabulate(&rows, Axis::Temp, Axis::Load, Value::OnboardMu0);
    assert_eq!((&t.rows, &t.cols), (&expect.rows, &expect.cols));
    assert!(t
        .cells
        .iter()
        .flatten()
        .any(|c| c.is_some_and(|c| c.n > 1 && c.sd.is_some())));
    for (x, y) in t.cells.iter().flatten().zip(expect.cells.iter().flatten()) {
        let (x, y) = (x.unwrap(), y.unwrap());
        assert_eq!(x.n, y.n);
        assert!((x.mean - y.mean).abs() < 1e-12);
        match (x.sd, y.sd) {
            (Some(a), Some(b)) => assert!((a - b).abs() <= 1e-9 * b.abs(), "{a} {b}"),
            (a, b) => assert_eq!(a, b),
        }
    }

    // A run half-received, synced, then completed by a pull: its row follows.
    let c = tempfile::tempdir().unwrap();
    let cfg = tribo_wire::Configure::real_rig(0.3);
    let mut meta = tribo_store::RunMeta::new(cfg);
    meta.device = Some(tribo_store::DeviceMeta {
        firmware: "0.1.0".into(),
        serial: "00000000000000c3".into(),
        protocol: tribo_wire::PROTOCOL_VERSION,
        port: "COM3".into(),
    });
    let mut w = tribo_store::RunWriter::create(c.path(), meta).unwrap();
    for f in tribo_testkit::frames(&cfg, 5, 6, 0, 3, 0.02) {
        w.append_frame(&f).unwrap();
    }
    let dir = w.dir().to_path_buf();
    w.checkpoint(tribo_store::RunStatus::Incomplete).unwrap();
    drop(w);
    let r = sync(c.path(), &url, &opts("pc-c"), &mut |_, _| {}).unwrap();
    assert_eq!(r.pushed.inserted, 1, "{r:?}");
    let before = lab.find("00000000000000c3/5").unwrap();
    assert_eq!(before.len(), 1);
    assert_eq!(before[0].run.row.blocks, 3);
    assert_ne!(before[0].run.row.status, "complete");
    std::thread::sleep(Duration::from_millis(20));
    let (mut w, _) = tribo_store::RunWriter::resume(&dir, false).unwrap();
    for f in tribo_testkit::frames(&cfg, 5, 6, 3, 6, 0.02)
        .into_iter()
        .skip(1)
    {
        w.file_frame(&f).unwrap();
    }
    w.finish(false).unwrap();
    let r = sync(c.path(), &url, &opts("pc-c"), &mut |_, _| {}).unwrap();
    assert_eq!(r.pushed.updated, 1, "{r:?}");
    let after = lab.find("00000000000000c3/5").unwrap();
    assert_eq!(
        (after[0].run.row.blocks, after[0].run.row.status.as_str()),
        (6, "complete")
    );
    assert_ne!(after[0].run.log_sha256, before[0].run.log_sha256);
    // An older, shorter copy of it on another PC never replaces the fuller one.
    let stale = lab.find("00000000000000c3/5").unwrap()[0].run.clone();
    let mut older = before[0].run.clone();
    older.pc = "pc-old".into();
    let counts = lab.push(&[older]).unwrap();
    assert_eq!(counts.kept, 1);
    assert_eq!(lab.find("00000000000000c3/5").unwrap()[0].run, stale);
    assert_eq!(pg.run_count(), 21);
}

#[test]
fn a_newer_schema_is_refused_and_an_older_one_is_migrated_once() {
    if PgServer::skip() {
        return;
    }
    let pg = PgServer::start();
    let url = pg.admin();
    // Several PCs meeting an empty catalog at once: one migrates, none fails.
    let handles: Vec<_> = (0..4)
        .map(|_| {
            let url = url.clone();
            std::thread::spawn(move || {
                LabCatalog::connect(&url).map(|c| c.schema_version().unwrap())
            })
        })
        .collect();
    for h in handles {
        assert_eq!(h.join().unwrap().unwrap(), tribo_catalog::schema::VERSION);
    }
    // One row per migration: each applied once.
    assert_eq!(
        pg.psql("lab", "SELECT count(*) FROM tribo_schema"),
        tribo_catalog::schema::VERSION.to_string()
    );
    pg.psql("lab", "INSERT INTO tribo_schema (version) VALUES (99)");
    let e = LabCatalog::connect(&url).unwrap_err().to_string();
    assert!(
        e.contains("schema version 99") && e.contains("update tribo"),
        "{e}"
    );
}

#[test]
fn a_role_without_write_rights_gets_a_clear_error_and_nothing_is_written() {
    if PgServer::skip() {
        return;
    }
    let pg = PgServer::start();
    let a = tempfile::tempdir().unwrap();
    store_of(a.path(), "00000000000000a1", 1, 3);
    LabCatalog::connect(&pg.admin()).unwrap();
    pg.psql(
        "lab",
        "CREATE ROLE reader LOGIN PASSWORD 'rpw'; GRANT SELECT ON tribo_runs, tribo_schema TO reader",
    );
    let reader = pg.lab_url("reader", "rpw", "lab");
    let e = sync(a.path(), &reader, &opts("pc-a"), &mut |_, _| {}).unwrap_err();
    let text = tribo_catalog::chain(&e);
    assert!(
        text.contains("\"reader\" may not") && text.contains("INSERT and UPDATE"),
        "{text}"
    );
    assert_eq!(pg.run_count(), 0);
    // It reads all the same.
    assert!(LabCatalog::connect(&reader)
        .unwrap()
        .runs(&Filter::default())
        .unwrap()
        .is_empty());
    // A wrong password: refused, the password never shown.
    let wrong = pg.lab_url("reader", "not-the-pw", "lab");
    let e = tribo_catalog::chain(&LabCatalog::connect(&wrong).unwrap_err());
    assert!(e.contains("refused the role \"reader\""), "{e}");
    assert!(!e.contains("not-the-pw"), "{e}");
    // A role that may not create the tables, on an empty database.
    pg.psql("postgres", "CREATE DATABASE empty");
    pg.psql("empty", "REVOKE CREATE ON SCHEMA public FROM PUBLIC");
    let e = LabCatalog::connect(&pg.lab_url("reader", "rpw", "empty"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("may not create tables") && e.contains("owner"),
        "{e}"
    );
}

#[test]
fn a_server_restarted_mid_sync_is_waited_for_and_nothing_is_lost_or_doubled() {
    if PgServer::skip() {
        return;
    }
    let pg = PgServer::start();
    let a = tempfile::tempdir().unwrap();
    store_of(a.path(), "00000000000000a1", 1, 120);
    let url = pg.admin();
    LabCatalog::connect(&url).unwrap();
    let (tx, rx) = mpsc::channel();
    let store = a.path().to_path_buf();
    let u = url.clone();
    let h = std::thread::spawn(move || {
        let mut o = opts("pc-a");
        o.batch = 5;
        sync(&store, &u, &o, &mut |done, _| {
            let _ = tx.send(done);
            std::thread::sleep(Duration::from_millis(20));
        })
    });
    rx.recv_timeout(Duration::from_secs(60)).unwrap();
    pg.stop();
    std::thread::sleep(Duration::from_millis(500));
    pg.start_again();
    let r = h.join().unwrap().unwrap();
    assert!(r.reconnects >= 1, "{r:?}");
    assert_eq!(pg.run_count(), 120);
    let again = sync(a.path(), &url, &opts("pc-a"), &mut |_, _| {}).unwrap();
    assert_eq!(again.unchanged, 120, "{again:?}");
}

#[test]
fn a_network_cut_fails_clearly_and_the_next_sync_sends_the_rest() {
    if PgServer::skip() {
        return;
    }
    let pg = PgServer::start();
    let a = tempfile::tempdir().unwrap();
    store_of(a.path(), "00000000000000a1", 1, 60);
    let url = pg.admin();
    LabCatalog::connect(&url).unwrap();
    let (tx, rx) = mpsc::channel();
    let store = a.path().to_path_buf();
    let u = url.clone();
    let h = std::thread::spawn(move || {
        let mut o = opts("pc-a");
        o.batch = 5;
        o.wait = Duration::from_secs(1);
        sync(&store, &u, &o, &mut |done, _| {
            let _ = tx.send(done);
            std::thread::sleep(Duration::from_millis(30));
        })
    });
    rx.recv_timeout(Duration::from_secs(60)).unwrap();
    pg.stop();
    let e = tribo_catalog::chain(&h.join().unwrap().unwrap_err());
    assert!(e.contains("run `tribo sync` again"), "{e}");
    // A sync while the server is away says so, in time.
    let t = std::time::Instant::now();
    let mut o = opts("pc-a");
    o.wait = Duration::from_secs(1);
    let e = tribo_catalog::chain(&sync(a.path(), &url, &o, &mut |_, _| {}).unwrap_err());
    assert!(e.contains("cannot be reached"), "{e}");
    assert!(t.elapsed() < Duration::from_secs(15));
    pg.start_again();
    let partial = pg.run_count();
    assert!(
        partial > 0 && partial < 60 && partial.is_multiple_of(5),
        "whole batches only: {partial}"
    );
    let r = sync(a.path(), &url, &opts("pc-a"), &mut |_, _| {}).unwrap();
    assert_eq!(
        (r.unchanged as usize, r.pushed.inserted as usize),
        (partial, 60 - partial),
        "{r:?}"
    );
    assert_eq!(pg.run_count(), 60);
}

#[test]
fn tls_when_the_url_asks_for_it_with_the_server_s_certificate_verified() {
    if PgServer::skip() {
        return;
    }
    let pg = PgServer::start();
    let ca = pg.enable_tls();
    let env = |k: &str| (k == "PGPASSWORD").then(|| tribo_testkit::ADMIN_PASSWORD.to_string());
    let base = format!(
        "postgres://{}@localhost:{}/lab",
        tribo_testkit::ADMIN,
        pg.port
    );
    let parse = |u: &str| tribo_catalog::LabUrl::parse_with(u, &env).unwrap();
    let tls = parse(&format!(
        "{base}?sslmode=verify-full&sslrootcert={}",
        ca.display()
    ));
    let lab = LabCatalog::connect(&tls).unwrap();
    assert!(lab.uses_tls().unwrap());
    let plain = LabCatalog::connect(&parse(&base)).unwrap();
    assert!(!plain.uses_tls().unwrap());
    // A certificate from an authority this PC was not given: refused, and said so.
    let e = tribo_catalog::chain(
        &LabCatalog::connect(&parse(&format!("{base}?sslmode=require"))).unwrap_err(),
    );
    assert!(e.contains("sslrootcert"), "{e}");
}

/// "Every run … this year, on any rig": `--since`/`--until` on the server select by the run's
/// day as each PC's own catalog does (both ends whole days, UTC), and a day not written
/// `YYYY-MM-DD` is refused.
#[test]
fn runs_of_a_period_across_rigs_as_each_pc_selects_them() {
    if PgServer::skip() {
        return;
    }
    let pg = PgServer::start();
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let days = [
        "2025-12-31T23:59:59Z",
        "2026-01-01T00:00:00Z",
        "2026-06-15T12:00:00Z",
    ];
    for (dir, serial) in [
        (a.path(), "00000000000000a1"),
        (b.path(), "00000000000000b2"),
    ] {
        for (i, created) in days.iter().enumerate() {
            synthetic_run(dir, serial, i as u32 + 1, 2, 0.01, |m| {
                m.created = created.to_string();
                m.label = Some(format!("DLC {i}"));
            });
        }
    }
    let url = pg.admin();
    for (dir, pc) in [(a.path(), "pc-a"), (b.path(), "pc-b")] {
        sync(dir, &url, &opts(pc), &mut |_, _| {}).unwrap();
    }
    let lab = LabCatalog::connect(&url).unwrap();
    let period = |since: Option<&str>, until: Option<&str>| Filter {
        since: since.map(Into::into),
        until: until.map(Into::into),
        ..Default::default()
    };
    let this_year = lab.runs(&period(Some("2026-01-01"), None)).unwrap();
    assert_eq!(this_year.len(), 4);
    let rigs: std::collections::BTreeSet<_> =
        this_year.iter().filter_map(|r| r.serial.clone()).collect();
    assert_eq!(rigs.len(), 2);
    assert!(this_year.iter().all(|r| r.created.starts_with("2026")));
    assert_eq!(
        lab.runs(&period(None, Some("2025-12-31"))).unwrap().len(),
        2
    );
    assert_eq!(
        lab.runs(&period(Some("2026-01-01"), Some("2026-01-01")))
            .unwrap()
            .len(),
        2
    );
    let local = tribo_store::RunCatalog::open(a.path()).unwrap();
    local.reindex().unwrap();
    for (s, u) in [(Some("2026-01-01"), None), (None, Some("2025-12-31"))] {
        let mine: Vec<String> = local
            .list(&period(s, u))
            .unwrap()
            .into_iter()
            .map(|r| r.created)
            .collect();
        let lab_mine: Vec<String> = lab
            .runs(&Filter {
                rig: Some("00000000000000a1".into()),
                ..period(s, u)
            })
            .unwrap()
            .into_iter()
            .map(|r| r.created)
            .collect();
        assert_eq!(mine, lab_mine);
    }
    let e = lab.runs(&period(Some("2026-1-1"), None)).unwrap_err();
    assert!(e.to_string().contains("YYYY-MM-DD"), "{e}");
}

/// Heater-off runs are one cell on the server as in each PC's table (`tabulate`), and the server's
/// half-up rounding of a 29.5 °C setpoint is Rust's. Rows synced before the server knew setpoints
/// (schema 1) read as their nominal temperature (a heater-off run at its plate's reading) until
/// their PC syncs again, which replaces them.
#[test]
fn heater_off_runs_are_one_cell_in_the_lab_and_rows_from_schema_1_are_mended_by_the_next_sync() {
    if PgServer::skip() {
        return;
    }
    let pg = PgServer::start();
    let url = pg.admin();
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    // (setpoint, load) of each run; rig a1 then rig b2. The plates read 41.5 °C (the synthetic
    // runs' header).
    let plan: [(Option<f64>, f64); 8] = [
        (None, 0.3),
        (None, 0.3),
        (Some(29.5), 0.3),
        (Some(30.4), 0.3),
        (None, 0.5),
        (Some(60.0), 0.5),
        (None, 0.3),
        (Some(29.5), 0.5),
    ];
    for (i, &(sp, load)) in plan.iter().enumerate() {
        let (dir, serial) = if i < 5 {
            (a.path(), "00000000000000a1")
        } else {
            (b.path(), "00000000000000b2")
        };
        synthetic_run(dir, serial, i as u32 + 1, 2, 0.01 + 0.001 * i as f32, |m| {
            m.campaign = Some("off".into());
            m.load_n = load;
            m.temp_setpoint_c = sp;
        });
    }
    let local = |d: &Path| {
        let cat = tribo_store::RunCatalog::open(d).unwrap();
        cat.refresh(false).unwrap();
        cat.list(&Filter::default()).unwrap()
    };
    let mut rows = local(a.path());
    rows.extend(local(b.path()));
    assert_eq!(rows.len(), 8);
    assert!(rows.iter().all(|r| r.status == "complete"));
    let expect = tribo_store::catalog::tabulate(&rows, Axis::Temp, Axis::Load, Value::OnboardMu0);
    let table = || {
        LabCatalog::connect(&url)
            .unwrap()
            .table(
                Axis::Temp,
                Axis::Load,
                Value::OnboardMu0,
                &Filter::default(),
            )
            .unwrap()
    };
    for (d, pc) in [(a.path(), "pc-a"), (b.path(), "pc-b")] {
        sync(d, &url, &opts(pc), &mut |_, _| {}).unwrap();
    }
    let same = |t: &tribo_store::catalog::Table| {
        assert_eq!(
            (&t.rows, &t.cols),
            (&expect.rows, &expect.cols),
            "{}",
            t.render()
        );
        for (x, y) in t.cells.iter().flatten().zip(expect.cells.iter().flatten()) {
            assert_eq!(x.map(|c| c.n), y.map(|c| c.n), "{}", t.render());
        }
    };
    let t = table();
    same(&t);
    assert_eq!(
        t.rows,
        [Bin::HeaterOff, Bin::SetpointC(30), Bin::SetpointC(60)],
        "{}",
        t.render()
    );
    assert_eq!(
        t.cells[0][0].unwrap().n,
        3,
        "heater off at 0.3 N, two rigs\n{}",
        t.render()
    );
    assert_eq!(
        t.cells[1][0].unwrap().n,
        2,
        "29.5 and 30.4 °C: 30 °C\n{}",
        t.render()
    );

    // The server as a tribo of schema 1 left it: no setpoint column. Migrated, its rows read as
    // their nominal temperatures (the heater-off runs at their plates' readings) ...
    pg.psql(
        "lab",
        "ALTER TABLE tribo_runs DROP COLUMN temp_setpoint_c; DELETE FROM tribo_schema WHERE version > 1",
    );
    let t = table();
    assert!(!t.rows.contains(&Bin::HeaterOff), "{}", t.render());
    assert!(t.rows.contains(&Bin::SetpointC(42)), "{}", t.render());
    // ... until each PC syncs again: every row is sent again and replaced.
    for (d, pc, n) in [(a.path(), "pc-a", 5), (b.path(), "pc-b", 3)] {
        let r = sync(d, &url, &opts(pc), &mut |_, _| {}).unwrap();
        assert_eq!((r.pushed.updated, r.unchanged), (n, 0), "{r:?}");
    }
    same(&table());
}
