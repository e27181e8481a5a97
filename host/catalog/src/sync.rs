//! `tribo sync`: a PC's runs into the lab catalog.
//!
//! Idempotent (a run the lab holds as this PC has it is not sent again), resumable (batches are
//! transactions: a sync killed midway left whole batches, the next one sends the rest), safe from
//! many PCs at once (one row per rig serial and rig run number, written in key order; a copy is
//! never replaced by a shorter one), and patient: a server that restarts or a network that drops
//! is waited for (`wait`), the batch in flight sent again.

use crate::lab::{is_transient, LabCatalog, LabRun, PushCounts};
use crate::url::LabUrl;
use crate::{caused, err, Result};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use tribo_store::catalog::log_stamp;
use tribo_store::run::{LOG_FILE, META_FILE};
use tribo_store::{CatalogRow, Filter, RunCatalog, RunMeta};

/// How to sync.
#[derive(Debug, Clone)]
pub struct SyncOptions {
    /// This PC's name in the lab catalog (default: its host name).
    pub pc: String,
    /// The store's folder as other PCs reach it (a shared folder), recorded as where the logs
    /// are; default: the store's own absolute path.
    pub shared_as: Option<PathBuf>,
    /// Runs per transaction.
    pub batch: usize,
    /// How long to wait for a server that cannot be reached (down, restarting, network cut).
    pub wait: Duration,
}

impl Default for SyncOptions {
    fn default() -> Self {
        SyncOptions {
            pc: host_name(),
            shared_as: None,
            batch: 200,
            wait: Duration::from_secs(60),
        }
    }
}

/// What a sync did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SyncReport {
    /// Runs in the local catalog.
    pub local: usize,
    /// Runs the lab already held as this PC has them (not sent).
    pub unchanged: usize,
    /// What the push did with the others.
    pub pushed: PushCounts,
    /// Runs the lab holds a fuller copy of (from another PC), not sent.
    pub fuller_elsewhere: usize,
    /// Run folders not synced, with why.
    pub skipped: Vec<(PathBuf, String)>,
    /// Times the server was lost and waited for.
    pub reconnects: usize,
}

/// This PC's host name (`COMPUTERNAME` on Windows, the kernel's on Linux, `HOSTNAME`), else
/// `unknown-pc`.
pub fn host_name() -> String {
    std::env::var("COMPUTERNAME")
        .ok()
        .or_else(|| std::fs::read_to_string("/proc/sys/kernel/hostname").ok())
        .or_else(|| std::fs::read_to_string("/etc/hostname").ok())
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "unknown-pc".into())
}

/// SHA-256 of a file, hex.
pub fn file_sha256(p: &Path) -> std::io::Result<String> {
    use sha2::Digest;
    use std::io::Read;
    let mut f = std::fs::File::open(p)?;
    let mut h = sha2::Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = f.read(&mut buf)?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
    }
    Ok(format!("{:x}", h.finalize()))
}

/// The local catalog of `store`, brought up to date with its folders first (as `tribo runs`
/// does), and its rows.
fn local_rows(store: &Path, report: &mut SyncReport) -> Result<Vec<CatalogRow>> {
    if !store.is_dir() {
        return Err(err(format!(
            "no run store at {}: point --store at the folder of this PC's runs",
            store.display()
        )));
    }
    let cat = RunCatalog::open(store)?;
    if let Some(r) = cat.refresh(false)? {
        report.skipped.extend(r.unreadable);
    }
    cat.list(&Filter::default())
}

/// The lab's copy of a local run, or why it cannot be placed in the lab.
fn lab_run(row: CatalogRow, opts: &SyncOptions) -> std::result::Result<LabRun, String> {
    let dir = row.path.clone();
    let meta: RunMeta = std::fs::read_to_string(dir.join(META_FILE))
        .map_err(|e| format!("{META_FILE}: {e}"))
        .and_then(|t| toml::from_str(&t).map_err(|e| format!("{META_FILE}: {e}")))?;
    let (Some(dev), Some(run_no)) = (meta.device.as_ref(), meta.device_run_id) else {
        return Err(
            "no rig serial number or rig run number (the run never reached its rig's header): \
             it cannot be told apart from other rigs' runs in the lab, not synced"
                .into(),
        );
    };
    // The on-board result's ± : in the run's results (`tribo run` saves them there), else read
    // from its log (the catalog row holds its μ only).
    let ob = std::fs::read_to_string(dir.join(tribo_store::run::RESULT_FILE))
        .ok()
        .and_then(|t| toml::from_str::<tribo_store::Results>(&t).ok())
        .and_then(|r| r.onboard)
        .or_else(|| {
            tribo_store::Run::open(&dir)
                .ok()
                .and_then(|r| r.result().copied())
        });
    let ob = ob.as_ref();
    let log = dir.join(LOG_FILE);
    let log_bytes = std::fs::metadata(&log)
        .map_err(|e| format!("{LOG_FILE}: {e}"))?
        .len() as i64;
    let stamp = log_stamp(&dir);
    let log_sha256 = file_sha256(&log).map_err(|e| format!("{LOG_FILE}: {e}"))?;
    let abs = std::path::absolute(&dir).unwrap_or(dir.clone());
    let log_dir = match &opts.shared_as {
        Some(shared) => shared.join(dir.file_name().unwrap_or_default()),
        None => abs,
    };
    let fin = |v: f32| Some(v as f64).filter(|v| v.is_finite());
    Ok(LabRun {
        rig_serial: dev.serial.clone(),
        rig_run: run_no as i64,
        pc: opts.pc.clone(),
        log_dir: log_dir.to_string_lossy().into_owned(),
        log_sha256,
        log_bytes,
        pc_stamp: stamp,
        onboard_mu0_se: ob.and_then(|r| fin(r.best.mu0_se)),
        onboard_mu1_se: ob.and_then(|r| fin(r.best.mu1_se)),
        row,
    })
}

/// A connection to the lab catalog, made again while the server cannot be reached, until
/// `deadline`.
fn connect_until(url: &LabUrl, deadline: Instant) -> Result<LabCatalog> {
    let mut pause = Duration::from_millis(100);
    loop {
        match LabCatalog::connect(url) {
            Ok(c) => return Ok(c),
            Err(e) => {
                let transient = std::error::Error::source(&e)
                    .and_then(|s| s.downcast_ref::<postgres::Error>())
                    .is_some_and(is_transient);
                if !transient || Instant::now() + pause > deadline {
                    return Err(e);
                }
                std::thread::sleep(pause);
                pause = (pause * 2).min(Duration::from_secs(2));
            }
        }
    }
}

/// Pushes the runs of the store at `store` to the lab catalog at `url`; `progress(done, todo)`
/// after each batch.
pub fn sync(
    store: &Path,
    url: &LabUrl,
    opts: &SyncOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SyncReport> {
    if opts.pc.trim().is_empty() || opts.pc.chars().any(char::is_control) {
        return Err(err("--pc: give this PC a name (letters, digits, dashes)"));
    }
    let mut report = SyncReport::default();
    let rows = local_rows(store, &mut report)?;
    report.local = rows.len();
    let mut serials: Vec<String> = rows.iter().filter_map(|r| r.serial.clone()).collect();
    serials.sort();
    serials.dedup();
    let wait = |from: Instant| from + opts.wait;
    let mut lab = connect_until(url, wait(Instant::now()))?;
    let known = lab.known(&serials)?;
    // What needs sending: rows the lab lacks, or holds otherwise than this PC now has them.
    let mut todo = Vec::new();
    for row in rows {
        let dir = row.path.clone();
        let key = row.serial.clone().zip(
            std::fs::read_to_string(dir.join(META_FILE))
                .ok()
                .and_then(|t| toml::from_str::<RunMeta>(&t).ok())
                .and_then(|m| m.device_run_id),
        );
        if let Some(k) = key.and_then(|(s, n)| known.get(&(s, n as i64))) {
            let bytes = std::fs::metadata(dir.join(LOG_FILE)).map_or(0, |m| m.len() as i64);
            // A fuller copy from anywhere, or as full a copy from another PC: the lab keeps it.
            if k.log_bytes > bytes || (k.log_bytes == bytes && k.pc != opts.pc) {
                report.fuller_elsewhere += 1;
                continue;
            }
            let here = match &opts.shared_as {
                Some(s) => s.join(dir.file_name().unwrap_or_default()),
                None => std::path::absolute(&dir).unwrap_or(dir.clone()),
            };
            if k.pc == opts.pc && k.pc_stamp == log_stamp(&dir) && Path::new(&k.log_dir) == here {
                report.unchanged += 1;
                continue;
            }
        }
        todo.push(row);
    }
    let total = todo.len();
    let mut done = 0;
    for chunk in todo.chunks(opts.batch.max(1)) {
        let mut runs = Vec::with_capacity(chunk.len());
        for row in chunk {
            match lab_run(row.clone(), opts) {
                Ok(r) => runs.push(r),
                Err(why) => report.skipped.push((row.path.clone(), why)),
            }
        }
        let deadline = wait(Instant::now());
        let counts = loop {
            match lab.push_raw(&runs) {
                Ok(c) => break c,
                Err(e) if is_transient(&e) && Instant::now() < deadline => {
                    // The transaction did not commit (or did, and sending it again changes
                    // nothing): reconnect and send the batch again.
                    report.reconnects += 1;
                    lab = connect_until(url, deadline).map_err(|e2| {
                        caused(
                            format!(
                                "the lab catalog at {} was lost mid-sync and did not come back within {} s: \
                                 {done} of {total} runs were sent, whole; run `tribo sync` again to send the rest",
                                url.shown(),
                                opts.wait.as_secs()
                            ),
                            e2,
                        )
                    })?;
                }
                Err(e) => {
                    return Err(crate::lab::explain(
                        url,
                        "writing runs to the lab catalog",
                        e,
                    ))
                }
            }
        };
        report.pushed.inserted += counts.inserted;
        report.pushed.updated += counts.updated;
        report.pushed.kept += counts.kept;
        done += chunk.len();
        progress(done, total);
    }
    Ok(report)
}
