//! The run catalog: one SQLite file (`catalog.sqlite` at the store's root) indexing every run of
//! the store (the lab catalog, on PostgreSQL, is `tribo-catalog`'s).
//!
//! It is an index, never the only copy: [`RunCatalog::reindex`] rebuilds it from the run folders.

use crate::run::{list_run_dirs, Run};
use crate::{ErrorKind, Result, StoreError};
use rusqlite::{params, Connection};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The catalog's file name at the store's root.
pub const CATALOG_FILE: &str = "catalog.sqlite";

/// The SQLite catalog's schema version (its `user_version`): a catalog of a newer tribo is
/// refused, not misread. Catalogs of earlier tribos (version 0) are migrated on opening.
pub const CATALOG_VERSION: i64 = 2;

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS runs (
    id TEXT PRIMARY KEY,
    path TEXT NOT NULL,
    created TEXT NOT NULL,
    status TEXT NOT NULL,
    label TEXT,
    sample TEXT,
    lubricant TEXT,
    campaign TEXT,
    repeat INTEGER,
    load_n REAL NOT NULL,
    temp_c REAL,
    firmware TEXT,
    serial TEXT,
    samples INTEGER NOT NULL,
    missing_blocks INTEGER NOT NULL,
    verdict TEXT,
    cycles INTEGER,
    onboard_mu0 REAL,
    onboard_mu1 REAL,
    host_mu0 REAL,
    host_mu1 REAL,
    host_gap REAL,
    lost_samples INTEGER NOT NULL DEFAULT 0,
    blocks INTEGER NOT NULL DEFAULT 0,
    blocks_expected INTEGER,
    completeness TEXT NOT NULL DEFAULT '',
    log_stamp TEXT NOT NULL DEFAULT '',
    host_mu0_se REAL,
    host_mu1_se REAL,
    temp_setpoint_c REAL
);
CREATE INDEX IF NOT EXISTS runs_campaign ON runs(campaign);
";

/// One catalogued run.
#[derive(Debug, Clone, PartialEq)]
pub struct CatalogRow {
    /// The run's id (its folder name).
    pub id: String,
    /// Its folder.
    pub path: PathBuf,
    /// Creation time, UTC (`YYYY-MM-DDTHH:MM:SSZ`).
    pub created: String,
    /// Its status (`complete`, `incomplete`, `aborted`, `recording`).
    pub status: String,
    /// Free-text label.
    pub label: Option<String>,
    /// The sample tested.
    pub sample: Option<String>,
    /// The lubricant.
    pub lubricant: Option<String>,
    /// The campaign it is part of.
    pub campaign: Option<String>,
    /// Its repetition index in the campaign (from 1).
    pub repeat: Option<u32>,
    /// Normal load (N).
    pub load_n: f64,
    /// Nominal temperature: the setpoint, else the measured one.
    pub temp_c: Option<f64>,
    /// The heater's setpoint; `None`: the heater was off (the run is at whatever the plate read).
    pub temp_setpoint_c: Option<f64>,
    /// The rig's firmware version.
    pub firmware: Option<String>,
    /// The rig's serial number.
    pub serial: Option<String>,
    /// Samples held.
    pub samples: u64,
    /// Sample blocks not received.
    pub missing_blocks: u64,
    /// The on-board analysis's verdict.
    pub verdict: Option<String>,
    /// Oscillation cycles until the stop (on-board count).
    pub cycles: Option<u32>,
    /// The on-board μ0 (Coulomb).
    pub onboard_mu0: Option<f64>,
    /// The on-board μ1 (viscous).
    pub onboard_mu1: Option<f64>,
    /// The host fit's μ0 (Coulomb).
    pub host_mu0: Option<f64>,
    /// The host fit's μ1 (viscous).
    pub host_mu1: Option<f64>,
    /// The host fit's envelope misfit, relative to the initial amplitude.
    pub host_gap: Option<f64>,
    /// Standard errors of the host fit's μ0 and μ1.
    pub host_mu0_se: Option<f64>,
    /// μ1's standard error.
    pub host_mu1_se: Option<f64>,
    /// Samples the rig lost (acquisition gaps reported by the run's gap frames).
    pub lost_samples: u64,
    /// Sample blocks held.
    pub blocks: u64,
    /// Blocks the run has (from its end frame; `None` when the end is missing).
    pub blocks_expected: Option<u64>,
    /// What the log holds, in one line: `complete: 156 of 156 blocks`, `incomplete: 79 of 156
    /// blocks (missing …)` ([`crate::Completeness::summary`]).
    pub completeness: String,
}

/// What [`RunCatalog::reindex`] found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Reindexed {
    /// Runs indexed.
    pub indexed: usize,
    /// Run folders that could not be read, with why.
    pub unreadable: Vec<(PathBuf, String)>,
    /// Runs indexed that are not stored whole, with their completeness (`incomplete: N of M
    /// blocks …`).
    pub incomplete: Vec<(PathBuf, String)>,
}

/// Which runs to list.
#[derive(Debug, Clone, Default)]
pub struct Filter {
    /// Runs of this campaign.
    pub campaign: Option<String>,
    /// Substring of the label.
    pub label: Option<String>,
    /// Runs with this status.
    pub status: Option<String>,
    /// Lowest load (N), included.
    pub load_min: Option<f64>,
    /// Highest load (N), included.
    pub load_max: Option<f64>,
    /// Lowest temperature (°C), included.
    pub temp_min: Option<f64>,
    /// Highest temperature (°C), included.
    pub temp_max: Option<f64>,
    /// Runs of this rig (its serial number).
    pub rig: Option<String>,
    /// Runs taken on or after this day (`YYYY-MM-DD`, UTC, as the run's `created`).
    pub since: Option<String>,
    /// Runs taken on or before this day (`YYYY-MM-DD`, UTC).
    pub until: Option<String>,
}

/// Whether `s` is a calendar day written `YYYY-MM-DD` (what the catalog's `created` begins with).
pub fn is_day(s: &str) -> bool {
    let b = s.as_bytes();
    let num = |r: std::ops::Range<usize>| -> Option<u32> {
        let t = s.get(r)?;
        t.bytes()
            .all(|c| c.is_ascii_digit())
            .then(|| t.parse().ok())?
    };
    b.len() == 10
        && b[4] == b'-'
        && b[7] == b'-'
        && num(0..4).is_some()
        && num(5..7).is_some_and(|m| (1..=12).contains(&m))
        && num(8..10).is_some_and(|d| (1..=31).contains(&d))
}

impl Filter {
    /// Whether nothing but the status is asked: the only listings a damaged run folder (one the
    /// catalog cannot hold, its campaign, rig, load, temperature and day unknown) belongs in.
    pub fn selects_by_status_only(&self) -> bool {
        let Filter {
            campaign,
            label,
            status: _,
            load_min,
            load_max,
            temp_min,
            temp_max,
            rig,
            since,
            until,
        } = self;
        campaign.is_none()
            && label.is_none()
            && load_min.is_none()
            && load_max.is_none()
            && temp_min.is_none()
            && temp_max.is_none()
            && rig.is_none()
            && since.is_none()
            && until.is_none()
    }

    /// Checks the filter: a known status, finite ranges whose minimum is not above the maximum. A
    /// filter that can match nothing by construction is an error, not an empty list.
    pub fn check(&self) -> Result<()> {
        if let Some(st) = &self.status {
            st.parse::<crate::RunStatus>()?;
        }
        for (what, lo, hi) in [
            ("load", self.load_min, self.load_max),
            ("temperature", self.temp_min, self.temp_max),
        ] {
            if lo.is_some_and(|v| !v.is_finite()) || hi.is_some_and(|v| !v.is_finite()) {
                return Err(StoreError::new(
                    ErrorKind::Invalid,
                    format!("{what} range must be finite"),
                ));
            }
            if let (Some(a), Some(b)) = (lo, hi) {
                if a > b {
                    return Err(StoreError::new(
                        ErrorKind::Invalid,
                        format!("{what} range {a}..{b} is empty: write the smaller bound first"),
                    ));
                }
            }
        }
        for (what, day) in [("since", &self.since), ("until", &self.until)] {
            if let Some(d) = day {
                if !is_day(d) {
                    return Err(StoreError::new(
                        ErrorKind::Invalid,
                        format!(
                            "--{what} {d:?} is not a day: write it YYYY-MM-DD, e.g. 2026-01-01"
                        ),
                    ));
                }
            }
        }
        if let (Some(a), Some(b)) = (&self.since, &self.until) {
            if a > b {
                return Err(StoreError::new(
                    ErrorKind::Invalid,
                    format!("--since {a} is after --until {b}: no run can be in between"),
                ));
            }
        }
        Ok(())
    }
}

/// What a campaign table's rows or columns are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    /// The normal load (N).
    Load,
    /// The heater's setpoint (°C; the heater off in a row of its own).
    Temp,
}

impl std::str::FromStr for Axis {
    type Err = StoreError;
    fn from_str(s: &str) -> Result<Axis> {
        match s {
            "load" => Ok(Axis::Load),
            "temp" | "temperature" => Ok(Axis::Temp),
            _ => Err(StoreError::new(
                ErrorKind::Invalid,
                format!("unknown axis {s:?}: use `load` or `temp`"),
            )),
        }
    }
}

/// The quantity a campaign table shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Value {
    /// Host fit's μ0 (Levenberg–Marquardt, as the thesis's tables).
    Mu0,
    /// Host fit's μ1.
    Mu1,
    /// The rig's own estimate of μ0.
    OnboardMu0,
    /// The rig's own estimate of μ1.
    OnboardMu1,
}

impl std::str::FromStr for Value {
    type Err = StoreError;
    fn from_str(s: &str) -> Result<Value> {
        match s {
            "mu0" => Ok(Value::Mu0),
            "mu1" => Ok(Value::Mu1),
            "onboard-mu0" => Ok(Value::OnboardMu0),
            "onboard-mu1" => Ok(Value::OnboardMu1),
            _ => Err(StoreError::new(
                ErrorKind::Invalid,
                format!("unknown value {s:?}: use mu0, mu1 (host fit), onboard-mu0 or onboard-mu1"),
            )),
        }
    }
}

/// Mean ± sample standard deviation over the repetitions in one cell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cell {
    /// The mean.
    pub mean: f64,
    /// Sample standard deviation (n − 1); `None` for a single run.
    pub sd: Option<f64>,
    /// How many runs.
    pub n: usize,
}

impl Cell {
    /// The mean and sample standard deviation of `values` (`None` for none).
    pub fn of(values: &[f64]) -> Option<Cell> {
        let n = values.len();
        if n == 0 {
            return None;
        }
        let (mean, sd) = tribo_physics::stats::mean_sd(values);
        Some(Cell {
            mean,
            sd: (n > 1).then_some(sd),
            n,
        })
    }
}

/// A campaign table: `cells[r][c]` for `rows[r]` × `cols[c]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// The row bins.
    pub rows: Vec<Bin>,
    /// The column bins.
    pub cols: Vec<Bin>,
    /// The cells, `cells[r][c]` (`None`: no run there).
    pub cells: Vec<Vec<Option<Cell>>>,
    /// What the rows bin.
    pub row_axis: Axis,
    /// What the columns bin.
    pub col_axis: Axis,
}

impl Table {
    /// The table of the cells `groups` (by row bin and column bin), rows and columns in bin order.
    pub fn of_groups(groups: BTreeMap<(Bin, Bin), Cell>, row_axis: Axis, col_axis: Axis) -> Table {
        let mut rows: Vec<Bin> = groups.keys().map(|k| k.0).collect();
        let mut cols: Vec<Bin> = groups.keys().map(|k| k.1).collect();
        rows.dedup();
        cols.sort_unstable();
        cols.dedup();
        Table {
            cells: rows
                .iter()
                .map(|a| {
                    cols.iter()
                        .map(|b| groups.get(&(*a, *b)).copied())
                        .collect()
                })
                .collect(),
            rows,
            cols,
            row_axis,
            col_axis,
        }
    }

    /// `rows`' values for JSON: N or °C, `null` for the heater off.
    pub fn row_values(&self) -> Vec<Option<f64>> {
        self.rows.iter().map(|b| b.value()).collect()
    }

    /// `cols`' values for JSON: N or °C, `null` for the heater off.
    pub fn col_values(&self) -> Vec<Option<f64>> {
        self.cols.iter().map(|b| b.value()).collect()
    }

    /// Text rendering: `mean ± sd (n)` per cell, `—` where no run was made.
    pub fn render(&self) -> String {
        let head = match self.row_axis {
            Axis::Load => "load \\ temp",
            Axis::Temp => "temp \\ load",
        };
        let mut grid: Vec<Vec<String>> = vec![std::iter::once(head.to_string())
            .chain(self.cols.iter().map(|c| c.label()))
            .collect()];
        for (r, row) in self.rows.iter().zip(&self.cells) {
            let mut line = vec![r.label()];
            for cell in row {
                line.push(match cell {
                    None => "—".into(),
                    Some(Cell {
                        mean,
                        sd: Some(sd),
                        n,
                    }) => format!("{mean:.5} ± {} ({n})", spread(*sd)),
                    Some(Cell { mean, sd: None, n }) => format!("{mean:.5} ({n})"),
                });
            }
            grid.push(line);
        }
        let ncol = grid[0].len();
        let widths: Vec<usize> = (0..ncol)
            .map(|c| grid.iter().map(|l| l[c].chars().count()).max().unwrap_or(0))
            .collect();
        let mut s = String::new();
        for l in &grid {
            for (c, cell) in l.iter().enumerate() {
                let pad = widths[c] - cell.chars().count();
                if c > 0 {
                    s.push_str("  ");
                }
                s.push_str(cell);
                s.push_str(&" ".repeat(pad));
            }
            let _ = writeln!(s);
        }
        s
    }
}

/// Either catalog: the run catalog (the store's own SQLite file, [`RunCatalog`]) or the lab catalog
/// (the lab's PostgreSQL server, `tribo_catalog::LabCatalog`). What `tribo runs`, `table`,
/// `campaign` and `report --campaign` read.
pub trait AnyCatalog {
    /// Runs matching `f`, oldest first; an invalid filter ([`Filter::check`]) is an error.
    fn runs(&self, f: &Filter) -> Result<Vec<CatalogRow>>;
    /// Where the catalog is, for messages (a folder, or a server's URL without any password).
    fn describe(&self) -> String;
    /// Campaign table of `value` over complete runs matching `f` ([`tabulate`]).
    fn table(&self, rows: Axis, cols: Axis, value: Value, f: &Filter) -> Result<Table> {
        Ok(tabulate(
            &self.runs(&table_filter(rows, cols, f)?)?,
            rows,
            cols,
            value,
        ))
    }
}

/// The runs a campaign table of `rows` × `cols` is made of: those of `f` that are complete (unless
/// `f` asks for a status). Rows and columns must differ.
pub fn table_filter(rows: Axis, cols: Axis, f: &Filter) -> Result<Filter> {
    if rows == cols {
        return Err(StoreError::new(
            ErrorKind::Invalid,
            "rows and columns must differ: use --rows temp --cols load",
        ));
    }
    let mut f = f.clone();
    f.status.get_or_insert_with(|| "complete".into());
    f.check()?;
    Ok(f)
}

impl AnyCatalog for RunCatalog {
    fn runs(&self, f: &Filter) -> Result<Vec<CatalogRow>> {
        self.list(f)
    }
    fn describe(&self) -> String {
        self.root.join(CATALOG_FILE).display().to_string()
    }
}

/// The frame log's size and modification time, `bytes:nanoseconds` (empty when unreadable): what
/// tells a catalogued run whose log changed since.
pub fn log_stamp(dir: &Path) -> String {
    std::fs::metadata(dir.join(crate::run::LOG_FILE))
        .ok()
        .map(|m| {
            let t = m
                .modified()
                .ok()
                .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
                .map_or(0, |d| d.as_nanos());
            format!("{}:{t}", m.len())
        })
        .unwrap_or_default()
}

/// The run catalog: the SQLite file of a store (`catalog.sqlite`) indexing its runs. (The lab
/// catalog, across PCs and rigs, is `tribo_catalog::LabCatalog` on PostgreSQL.)
pub struct RunCatalog {
    conn: Connection,
    root: PathBuf,
}

/// The run catalog's former name, kept so that code written against it (on branches not merged
/// yet) still builds; new code says [`RunCatalog`].
pub type Catalog = RunCatalog;

fn db_err(ctx: &str, e: rusqlite::Error) -> StoreError {
    StoreError::caused(
        ErrorKind::Catalog,
        format!("catalog: {ctx} (the catalog is only an index: delete catalog.sqlite and run `tribo runs --reindex`)"),
        e,
    )
}

impl RunCatalog {
    /// Opens (or creates) the catalog of the store at `root`.
    pub fn open(root: &Path) -> Result<RunCatalog> {
        std::fs::create_dir_all(root).map_err(|e| {
            StoreError::io(format!("cannot create the store {}", root.display()), e)
        })?;
        let conn = Connection::open(root.join(CATALOG_FILE)).map_err(|e| db_err("open", e))?;
        conn.busy_timeout(std::time::Duration::from_secs(5))
            .map_err(|e| db_err("open", e))?;
        let version: i64 = conn
            .query_row("PRAGMA user_version", [], |r| r.get(0))
            .map_err(|e| db_err("open", e))?;
        if version > CATALOG_VERSION {
            return Err(StoreError::new(
                ErrorKind::Catalog,
                format!(
                    "{} was written by a newer tribo (catalog version {version}, this tribo knows up to \
                     {CATALOG_VERSION}): update tribo, or move it away and run `tribo runs --reindex` \
                     (the catalog is only an index of the run folders)",
                    root.join(CATALOG_FILE).display()
                ),
            ));
        }
        conn.execute_batch(SCHEMA)
            .map_err(|e| db_err("schema", e))?;
        // A catalog made by an earlier tribo: add the columns it lacks (acquisition gaps: its runs
        // ended at their first overrun, so they have none; block counts and completeness: filled
        // in by the next re-index, which `tribo runs` makes when it sees them empty).
        for (column, decl) in [
            ("lost_samples", "INTEGER NOT NULL DEFAULT 0"),
            ("blocks", "INTEGER NOT NULL DEFAULT 0"),
            ("blocks_expected", "INTEGER"),
            ("completeness", "TEXT NOT NULL DEFAULT ''"),
            ("log_stamp", "TEXT NOT NULL DEFAULT ''"),
            ("host_mu0_se", "REAL"),
            ("host_mu1_se", "REAL"),
            ("temp_setpoint_c", "REAL"),
        ] {
            let has: bool = conn
                .query_row(
                    "SELECT COUNT(*) FROM pragma_table_info('runs') WHERE name = ?1",
                    [column],
                    |r| r.get::<_, i64>(0),
                )
                .map_err(|e| db_err("schema", e))?
                > 0;
            if !has {
                conn.execute_batch(&format!("ALTER TABLE runs ADD COLUMN {column} {decl}"))
                    .map_err(|e| db_err("schema", e))?;
            }
        }
        if version < 2 {
            // Version 2 tells a heater-off run from one held at a setpoint: the rows of an earlier
            // catalog do not know, so they are marked stale and rebuilt from the run folders by the
            // next [`RunCatalog::refresh`].
            conn.execute_batch("UPDATE runs SET log_stamp = ''")
                .map_err(|e| db_err("schema", e))?;
        }
        if version < CATALOG_VERSION {
            conn.pragma_update(None, "user_version", CATALOG_VERSION)
                .map_err(|e| db_err("schema", e))?;
        }
        Ok(RunCatalog {
            conn,
            root: root.to_owned(),
        })
    }

    /// The store's root folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Adds or updates a run.
    pub fn upsert(&self, run: &Run) -> Result<()> {
        let m = &run.meta;
        let samples: u64 = run.blocks().map(|b| b.samples() as u64).sum();
        let ob = run.result();
        let host = run.host_fit();
        let c = run.completeness();
        self.conn
            .execute(
                "INSERT OR REPLACE INTO runs (id,path,created,status,label,sample,lubricant,campaign,repeat,\
                 load_n,temp_c,firmware,serial,samples,missing_blocks,verdict,cycles,onboard_mu0,onboard_mu1,\
                 host_mu0,host_mu1,host_gap,lost_samples,blocks,blocks_expected,completeness,log_stamp,host_mu0_se,host_mu1_se,\
                 temp_setpoint_c) \
                 VALUES (?1,?2,?3,?4,?5,?6,?7,?8,?9,?10,?11,?12,?13,?14,?15,?16,?17,?18,?19,?20,?21,?22,?23,?24,?25,?26,?27,?28,?29,?30)",
                params![
                    m.id,
                    run.dir().to_string_lossy(),
                    m.created,
                    m.status.name(),
                    m.label,
                    m.sample,
                    m.lubricant,
                    m.campaign,
                    m.repeat,
                    m.load_n,
                    m.nominal_temp_c(),
                    m.device.as_ref().map(|d| d.firmware.clone()),
                    m.device.as_ref().map(|d| d.serial.clone()),
                    samples as i64,
                    c.missing.len() as i64,
                    ob.map(|r| r.verdict.name()),
                    ob.map(|r| r.cycles),
                    ob.map(|r| r.best.mu0 as f64).filter(|v| v.is_finite()),
                    ob.map(|r| r.best.mu1 as f64).filter(|v| v.is_finite()),
                    host.map(|h| h.mu0).filter(|v| v.is_finite()),
                    host.map(|h| h.mu1).filter(|v| v.is_finite()),
                    host.map(|h| h.gap).filter(|v| v.is_finite()),
                    run.lost_samples() as i64,
                    c.blocks_held as i64,
                    c.blocks_expected.map(|b| b as i64),
                    c.summary(),
                    log_stamp(run.dir()),
                    host.map(|h| h.mu0_se).filter(|v| v.is_finite()),
                    host.map(|h| h.mu1_se).filter(|v| v.is_finite()),
                    m.temp_setpoint_c,
                ],
            )
            .map_err(|e| db_err("insert", e))?;
        Ok(())
    }

    /// Rebuilds the catalog from the run folders, each run's status and completeness read from its
    /// frame log (never from what its metadata claims). Returns what was indexed, the folders that
    /// could not be read (with why) and the runs that are not stored whole.
    pub fn reindex(&self) -> Result<Reindexed> {
        self.conn
            .execute("DELETE FROM runs", [])
            .map_err(|e| db_err("reindex", e))?;
        let mut out = Reindexed::default();
        for dir in list_run_dirs(&self.root)? {
            match Run::open(&dir) {
                Ok(run) => {
                    self.upsert(&run)?;
                    out.indexed += 1;
                    let c = run.completeness();
                    if !c.is_complete() {
                        let mut why = c.summary();
                        if let Some(r) = &run.recovery {
                            why.push_str(&format!("; the log: {r}"));
                        }
                        out.incomplete.push((dir, why));
                    }
                }
                Err(e) => out.unreadable.push((dir, e.msg)),
            }
        }
        Ok(out)
    }

    /// Brings the catalog up to date with the run folders: rebuilt ([`RunCatalog::reindex`]) when
    /// `force`, when it does not know a folder (a killed recorder, runs copied in), when a log
    /// changed since it was catalogued (a pull completed it, a copy truncated it, [`RunCatalog::stale`])
    /// or when its rows come from a tribo that did not record what this one reads. Returns what
    /// the rebuild found, `None` when the catalog was already up to date. What every reader of a
    /// store's catalog calls first.
    pub fn refresh(&self, force: bool) -> Result<Option<Reindexed>> {
        let folders = list_run_dirs(&self.root)?.len();
        let rows = self.list(&Filter::default())?;
        if force
            || folders != rows.len()
            || rows.iter().any(|r| r.completeness.is_empty())
            || !self.stale()?.is_empty()
        {
            return self.reindex().map(Some);
        }
        Ok(None)
    }

    /// Run folders whose frame log changed (size or time) since they were catalogued, or that the
    /// catalog does not know: its rows for them may say what the logs no longer hold.
    pub fn stale(&self) -> Result<Vec<PathBuf>> {
        let mut stmt = self
            .conn
            .prepare("SELECT id, log_stamp FROM runs")
            .map_err(|e| db_err("query", e))?;
        let known: BTreeMap<String, String> = stmt
            .query_map([], |r| Ok((r.get::<_, String>(0)?, r.get::<_, String>(1)?)))
            .map_err(|e| db_err("query", e))?
            .collect::<std::result::Result<_, _>>()
            .map_err(|e| db_err("query", e))?;
        Ok(list_run_dirs(&self.root)?
            .into_iter()
            .filter(|d| {
                let id = d.file_name().map(|n| n.to_string_lossy().into_owned());
                id.and_then(|id| known.get(&id)) != Some(&log_stamp(d))
            })
            .collect())
    }

    /// Runs matching `f`, oldest first; an invalid filter ([`Filter::check`]) is an error.
    pub fn list(&self, f: &Filter) -> Result<Vec<CatalogRow>> {
        f.check()?;
        let mut stmt = self
            .conn
            .prepare(
                "SELECT id,path,created,status,label,sample,lubricant,campaign,repeat,load_n,temp_c,firmware,serial,\
                 samples,missing_blocks,verdict,cycles,onboard_mu0,onboard_mu1,host_mu0,host_mu1,host_gap,lost_samples,\
                 blocks,blocks_expected,completeness,host_mu0_se,host_mu1_se,temp_setpoint_c FROM runs \
                 WHERE (?1 IS NULL OR campaign = ?1) AND (?2 IS NULL OR instr(label, ?2) > 0) \
                 AND (?3 IS NULL OR status = ?3) AND (?4 IS NULL OR load_n >= ?4 - 1e-9) \
                 AND (?5 IS NULL OR load_n <= ?5 + 1e-9) AND (?6 IS NULL OR temp_c >= ?6 - 1e-9) \
                 AND (?7 IS NULL OR temp_c <= ?7 + 1e-9) AND (?8 IS NULL OR serial = ?8) \
                 AND (?9 IS NULL OR substr(created, 1, 10) >= ?9) \
                 AND (?10 IS NULL OR substr(created, 1, 10) <= ?10) ORDER BY created, id",
            )
            .map_err(|e| db_err("query", e))?;
        let rows = stmt
            .query_map(
                params![
                    f.campaign, f.label, f.status, f.load_min, f.load_max, f.temp_min, f.temp_max,
                    f.rig, f.since, f.until
                ],
                |r| {
                    Ok(CatalogRow {
                        id: r.get(0)?,
                        // A run folder lives in the store: where this catalog was opened from
                        // (a store catalogued as `runs` and opened as `/lab/runs`, or from
                        // another folder, is the same store with the same runs).
                        path: {
                            let p = PathBuf::from(r.get::<_, String>(1)?);
                            p.file_name().map_or(p.clone(), |n| self.root.join(n))
                        },
                        created: r.get(2)?,
                        status: r.get(3)?,
                        label: r.get(4)?,
                        sample: r.get(5)?,
                        lubricant: r.get(6)?,
                        campaign: r.get(7)?,
                        repeat: r.get(8)?,
                        load_n: r.get(9)?,
                        temp_c: r.get(10)?,
                        temp_setpoint_c: r.get(28)?,
                        firmware: r.get(11)?,
                        serial: r.get(12)?,
                        samples: r.get::<_, i64>(13)? as u64,
                        missing_blocks: r.get::<_, i64>(14)? as u64,
                        verdict: r.get(15)?,
                        cycles: r.get(16)?,
                        onboard_mu0: r.get(17)?,
                        onboard_mu1: r.get(18)?,
                        host_mu0: r.get(19)?,
                        host_mu1: r.get(20)?,
                        host_gap: r.get(21)?,
                        lost_samples: r.get::<_, i64>(22)? as u64,
                        blocks: r.get::<_, i64>(23)? as u64,
                        blocks_expected: r.get::<_, Option<i64>>(24)?.map(|b| b as u64),
                        completeness: r.get(25)?,
                        host_mu0_se: r.get(26)?,
                        host_mu1_se: r.get(27)?,
                    })
                },
            )
            .map_err(|e| db_err("query", e))?;
        rows.collect::<std::result::Result<Vec<_>, _>>()
            .map_err(|e| db_err("query", e))
    }
}

/// Where a run sits on one axis of a campaign table or figure: the one binning rule that `tribo
/// table`, the lab catalog's server-side table, `tribo campaign`'s summary, the front panel's grid
/// and the campaign report's figures share.
///
/// Loads go to the mN, setpoints to the °C, both rounded half up (`floor(x + 0.5)`, which the lab
/// catalog's SQL computes to the same integer). A run with the heater off is in one
/// [`Bin::HeaterOff`] cell whatever its plate read: room temperature is not a setting, and a run at
/// 22.4 °C and one at 38.8 °C (the plate warmed by the day, or read just after the knob moved) are
/// repetitions of the same condition.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Bin {
    /// A load, in mN.
    LoadMn(i64),
    /// The heater off (sorted before every setpoint).
    HeaterOff,
    /// A heater setpoint, in °C.
    SetpointC(i64),
}

impl Bin {
    /// The bin of `r` on axis `a`; `None` when the run has no finite value there.
    pub fn of(a: Axis, r: &CatalogRow) -> Option<Bin> {
        match a {
            Axis::Load => Bin::load(r.load_n),
            Axis::Temp => Bin::temp(r.temp_setpoint_c),
        }
    }

    /// A load's bin (N in, mN bin).
    pub fn load(load_n: f64) -> Option<Bin> {
        half_up(load_n * 1000.0).map(Bin::LoadMn)
    }

    /// A run's temperature bin from its setpoint (`None`: the heater off).
    pub fn temp(setpoint_c: Option<f64>) -> Option<Bin> {
        match setpoint_c {
            None => Some(Bin::HeaterOff),
            Some(t) => half_up(t).map(Bin::SetpointC),
        }
    }

    /// The bin's value: N for a load, °C for a setpoint, `None` for the heater off.
    pub fn value(self) -> Option<f64> {
        match self {
            Bin::LoadMn(mn) => Some(mn as f64 * 1e-3),
            Bin::SetpointC(c) => Some(c as f64),
            Bin::HeaterOff => None,
        }
    }

    /// How a table or a legend names it: `0.300 N`, `60 °C`, `heater off`.
    pub fn label(self) -> String {
        match self {
            Bin::LoadMn(mn) => format!("{:.3} N", mn as f64 * 1e-3),
            Bin::SetpointC(c) => format!("{c} °C"),
            Bin::HeaterOff => "heater off".into(),
        }
    }
}

/// `floor(x + 0.5)` as an integer, for a finite `x` within ±1e15.
fn half_up(x: f64) -> Option<i64> {
    (x.is_finite() && x.abs() < 1e15).then(|| (x + 0.5).floor() as i64)
}

/// The campaign table of `value` over `runs`: mean ± sd over repetitions for each (row, column)
/// pair of [`Bin`]s.
pub fn tabulate(runs: &[CatalogRow], rows: Axis, cols: Axis, value: Value) -> Table {
    let mut groups: BTreeMap<(Bin, Bin), Vec<f64>> = BTreeMap::new();
    for r in runs {
        let (Some(a), Some(b)) = (Bin::of(rows, r), Bin::of(cols, r)) else {
            continue;
        };
        let v = match value {
            Value::Mu0 => r.host_mu0,
            Value::Mu1 => r.host_mu1,
            Value::OnboardMu0 => r.onboard_mu0,
            Value::OnboardMu1 => r.onboard_mu1,
        };
        let Some(v) = v.filter(|v| v.is_finite()) else {
            continue;
        };
        groups.entry((a, b)).or_default().push(v);
    }
    Table::of_groups(
        groups
            .into_iter()
            .filter_map(|(k, v)| Some((k, Cell::of(&v)?)))
            .collect(),
        rows,
        cols,
    )
}

/// A spread as a table shows it: five decimals, as the means, unless that rounds a spread that is
/// there to nothing (`± 0.00000` hid spreads of 5e-7): then two significant digits.
fn spread(sd: f64) -> String {
    if sd != 0.0 && sd.abs() < 5e-6 {
        format!("{sd:.1e}")
    } else {
        format!("{sd:.5}")
    }
}

#[cfg(test)]
mod spread_tests {
    use super::spread;

    #[test]
    fn a_spread_below_the_fifth_decimal_is_not_shown_as_zero() {
        assert_eq!(spread(5e-7), "5.0e-7");
        assert_eq!(spread(0.0), "0.00000");
        assert_eq!(spread(1.2e-4), "0.00012");
        assert_eq!(spread(5e-6), "0.00001");
    }
}
