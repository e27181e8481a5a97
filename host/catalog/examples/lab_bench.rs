//! The lab catalog's benchmark: PCS simulated PCs (threads, each with its own connection) push
//! RUNS runs each into one PostgreSQL server started in a temporary folder, then the cross-rig
//! queries a lab asks (every DLC run at 60 °C on any rig; a campaign table) run over all of them.
//! Last, one real `sync` of a store of synthetic run folders (reading, hashing, pushing).
//!
//! `cargo run --release -p tribo-catalog --example lab_bench -- [PCS] [RUNS] [FOLDERS]`
//! (defaults 10, 10000, 1000).

use std::time::{Duration, Instant};
use tribo_catalog::{AnyCatalog, LabCatalog, LabRun};
use tribo_store::catalog::{Axis, Value};
use tribo_store::{CatalogRow, Filter};
use tribo_testkit::{synthetic_run, PgServer};

fn run(pc: usize, i: usize) -> LabRun {
    let load = [0.1, 0.2, 0.3, 0.4][i % 4];
    let temp = [25.0, 40.0, 60.0, 80.0][(i / 4) % 4];
    let mu0 = 0.01 + 0.02 * load + 1e-4 * temp + 1e-5 * (i % 7) as f64;
    LabRun {
        rig_serial: format!("{:016x}", 0xa000 + pc),
        rig_run: i as i64 + 1,
        pc: format!("pc{pc}"),
        log_dir: format!("/lab/pc{pc}/runs/run-{i}"),
        log_sha256: format!("{:064x}", pc * 1_000_000 + i),
        log_bytes: 400_000,
        pc_stamp: format!("400000:{i}"),
        onboard_mu0_se: Some(1e-4),
        onboard_mu1_se: Some(2e-5),
        row: CatalogRow {
            id: format!("2026{:04}T1200Z-N{load:.3}-T{temp:.0}", i % 10_000),
            path: format!("/lab/pc{pc}/runs/run-{i}").into(),
            created: format!("2026-{:02}-{:02}T12:00:00Z", 1 + i % 12, 1 + i % 28),
            status: "complete".into(),
            label: Some(
                if i.is_multiple_of(3) {
                    "DLC on steel"
                } else {
                    "steel on steel"
                }
                .into(),
            ),
            sample: Some("AISI 52100".into()),
            lubricant: Some("PAO 6".into()),
            campaign: Some(format!("campaign-{}", i % 50)),
            repeat: Some((i % 3) as u32 + 1),
            load_n: load,
            temp_c: Some(temp),
            temp_setpoint_c: Some(temp),
            firmware: Some("0.1.0".into()),
            serial: Some(format!("{:016x}", 0xa000 + pc)),
            samples: 20_000,
            missing_blocks: 0,
            verdict: Some("ok".into()),
            cycles: Some(40),
            onboard_mu0: Some(mu0),
            onboard_mu1: Some(0.01),
            host_mu0: Some(mu0 * 1.001),
            host_mu1: Some(0.01),
            host_gap: Some(1e-3),
            host_mu0_se: Some(1e-5),
            host_mu1_se: Some(1e-6),
            lost_samples: 0,
            blocks: 79,
            blocks_expected: Some(79),
            completeness: "complete: 79 of 79 blocks".into(),
        },
    }
}

fn time<T>(f: impl FnOnce() -> T) -> (T, Duration) {
    let t = Instant::now();
    let r = f();
    (r, t.elapsed())
}

fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("PCS RUNS FOLDERS: numbers"))
        .collect();
    let pcs = args.first().copied().unwrap_or(10);
    let runs = args.get(1).copied().unwrap_or(10_000);
    let folders = args.get(2).copied().unwrap_or(1000);
    let pg = PgServer::start();
    let url = pg.admin();
    LabCatalog::connect(&url).expect("the catalog's tables");
    let ((), push) = time(|| {
        let hs: Vec<_> = (0..pcs)
            .map(|pc| {
                let url = url.clone();
                std::thread::spawn(move || {
                    let lab = LabCatalog::connect(&url).unwrap();
                    let all: Vec<LabRun> = (0..runs).map(|i| run(pc, i)).collect();
                    for b in all.chunks(200) {
                        lab.push(b).unwrap();
                    }
                })
            })
            .collect();
        for h in hs {
            h.join().unwrap();
        }
    });
    let total = pcs * runs;
    println!(
        "{pcs} PCs × {runs} runs = {total} runs pushed in {:.2} s: {:.0} runs/s (batches of 200, one transaction each)",
        push.as_secs_f64(),
        total as f64 / push.as_secs_f64()
    );
    // Again, as a second sync of unchanged PCs would send them if it did not skip them.
    let lab = LabCatalog::connect(&url).unwrap();
    let (_, again) = time(|| {
        let all: Vec<LabRun> = (0..runs).map(|i| run(0, i)).collect();
        for b in all.chunks(200) {
            lab.push(b).unwrap();
        }
    });
    println!(
        "one PC's {runs} runs pushed again, unchanged (all kept): {:.2} s",
        again.as_secs_f64()
    );
    pg.psql("lab", "ANALYZE tribo_runs");
    let f = Filter {
        label: Some("DLC".into()),
        temp_min: Some(59.5),
        temp_max: Some(60.5),
        ..Default::default()
    };
    for round in 0..2 {
        let (rows, q) = time(|| lab.runs(&f).unwrap());
        let rigs: std::collections::BTreeSet<_> =
            rows.iter().filter_map(|r| r.serial.clone()).collect();
        let (t, tq) = time(|| {
            lab.table(Axis::Temp, Axis::Load, Value::Mu0, &Filter::default())
                .unwrap()
        });
        let n: usize = t.cells.iter().flatten().flatten().map(|c| c.n).sum();
        println!(
            "{} cross-rig query \"DLC at 60 °C, any rig\": {} runs of {} rigs in {:.0} ms; \
             campaign table over all {n} runs ({}×{} cells) in {:.0} ms",
            if round == 0 { "cold" } else { "warm" },
            rows.len(),
            rigs.len(),
            q.as_secs_f64() * 1e3,
            t.rows.len(),
            t.cols.len(),
            tq.as_secs_f64() * 1e3
        );
    }
    if folders > 0 {
        let store = tempfile::tempdir().unwrap();
        for i in 0..folders {
            synthetic_run(
                store.path(),
                "00000000000000f0",
                i as u32 + 1,
                79,
                0.02,
                |_| {},
            );
        }
        let (_, ri) = time(|| {
            tribo_store::RunCatalog::open(store.path())
                .unwrap()
                .reindex()
                .unwrap()
        });
        println!(
            "the local catalog of those {folders} folders rebuilt from their logs first (as `tribo runs` does): {:.2} s",
            ri.as_secs_f64()
        );
        let opts = tribo_catalog::SyncOptions {
            pc: "pc-real".into(),
            ..Default::default()
        };
        let (r, s) =
            time(|| tribo_catalog::sync(store.path(), &url, &opts, &mut |_, _| {}).unwrap());
        let (r2, s2) =
            time(|| tribo_catalog::sync(store.path(), &url, &opts, &mut |_, _| {}).unwrap());
        println!(
            "tribo sync of {} run folders (79 blocks each, logs read and hashed): {:.2} s ({:.0} runs/s); \
             the same again, nothing to send ({} unchanged): {:.2} s",
            r.pushed.inserted,
            s.as_secs_f64(),
            r.pushed.inserted as f64 / s.as_secs_f64(),
            r2.unchanged,
            s2.as_secs_f64()
        );
    }
}
