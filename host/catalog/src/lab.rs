//! The lab catalog on a PostgreSQL server.

use crate::schema::{CREATE_VERSION_TABLE, LOCK, MIGRATIONS, VERSION};
use crate::url::{LabUrl, Tls};
use crate::{caused, err, Result};
use postgres::error::SqlState;
use postgres::types::ToSql;
use postgres::Client;
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;
use tribo_store::catalog::{table_filter, AnyCatalog, Axis, Bin, Cell, Table, Value};
use tribo_store::{CatalogRow, Filter, StoreError};

/// One run as pushed to the lab catalog: the local catalog's row and what places it in the lab.
#[derive(Debug, Clone, PartialEq)]
pub struct LabRun {
    /// The rig's serial number and its own number for the run: the run's key in the lab.
    pub rig_serial: String,
    /// The rig's own number for the run.
    pub rig_run: i64,
    /// The PC that holds the frame log (its host name, or `--pc`).
    pub pc: String,
    /// The run folder as that PC (or, for a shared folder, every PC) reaches it.
    pub log_dir: String,
    /// SHA-256 of the frame log, hex.
    pub log_sha256: String,
    /// The frame log's size, bytes.
    pub log_bytes: i64,
    /// The log's size and time on its PC ([`tribo_store::catalog::log_stamp`]): what tells the
    /// next sync the run changed.
    pub pc_stamp: String,
    /// On-board standard error of μ0.
    pub onboard_mu0_se: Option<f64>,
    /// On-board standard error of μ1.
    pub onboard_mu1_se: Option<f64>,
    /// Everything else, as the local catalog holds it (`row.id`: the run folder's name).
    pub row: CatalogRow,
}

/// One run read back from the lab catalog.
#[derive(Debug, Clone, PartialEq)]
pub struct LabRow {
    /// The run as it was pushed.
    pub run: LabRun,
    /// When it was last written (server time, RFC 3339).
    pub synced_at: String,
}

/// What one push did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PushCounts {
    /// Runs the lab did not have.
    pub inserted: usize,
    /// Runs whose row changed (a longer log, new results, a new place).
    pub updated: usize,
    /// Runs left as they were: the same, or the lab holds a fuller copy from another PC.
    pub kept: usize,
}

/// What the lab knows of a run, to decide whether a PC's copy needs pushing.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Known {
    /// The PC whose copy the lab holds.
    pub pc: String,
    /// Where that PC keeps the run folder.
    pub log_dir: String,
    /// The log's size and time on that PC ([`LabRun::pc_stamp`]).
    pub pc_stamp: String,
    /// The log's size, bytes.
    pub log_bytes: i64,
}

const COLUMNS: &str = "rig_serial,rig_run,run_id,pc,log_dir,log_sha256,log_bytes,pc_stamp,row_hash,\
created,status,label,sample,lubricant,campaign,repeat,load_n,temp_c,firmware,samples,missing_blocks,\
verdict,cycles,onboard_mu0,onboard_mu1,onboard_mu0_se,onboard_mu1_se,host_mu0,host_mu1,host_gap,\
host_mu0_se,host_mu1_se,lost_samples,blocks,blocks_expected,completeness,temp_setpoint_c";

/// The rows a [`Filter`] keeps ([`filter_params`] are its parameters $1..$10).
const FILTER: &str = "WHERE ($1::text IS NULL OR campaign = $1) AND ($2::text IS NULL OR strpos(label, $2) > 0) \
     AND ($3::text IS NULL OR status = $3) AND ($4::float8 IS NULL OR load_n >= $4 - 1e-9) \
     AND ($5::float8 IS NULL OR load_n <= $5 + 1e-9) AND ($6::float8 IS NULL OR temp_c >= $6 - 1e-9) \
     AND ($7::float8 IS NULL OR temp_c <= $7 + 1e-9) AND ($8::text IS NULL OR rig_serial = $8) \
     AND ($9::text IS NULL OR substr(created, 1, 10) >= $9) \
     AND ($10::text IS NULL OR substr(created, 1, 10) <= $10)";

fn filter_params(f: &Filter) -> [&(dyn ToSql + Sync); 10] {
    [
        &f.campaign,
        &f.label,
        &f.status,
        &f.load_min,
        &f.load_max,
        &f.temp_min,
        &f.temp_max,
        &f.rig,
        &f.since,
        &f.until,
    ]
}

/// The lab catalog: a connection to the server, its schema checked (and migrated) on connecting.
pub struct LabCatalog {
    client: RefCell<Client>,
    url: LabUrl,
}

impl std::fmt::Debug for LabCatalog {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LabCatalog")
            .field("url", &self.url.shown())
            .finish()
    }
}

/// Whether a failure may pass if tried again: the server unreachable, restarting or shut down,
/// the connection lost, a deadlock or serialization failure between PCs.
pub fn is_transient(e: &postgres::Error) -> bool {
    if let Some(c) = e.code() {
        return c.code().starts_with("08")
            || [
                SqlState::ADMIN_SHUTDOWN,
                SqlState::CRASH_SHUTDOWN,
                SqlState::CANNOT_CONNECT_NOW,
                SqlState::T_R_DEADLOCK_DETECTED,
                SqlState::T_R_SERIALIZATION_FAILURE,
                SqlState::TOO_MANY_CONNECTIONS,
            ]
            .contains(c);
    }
    e.is_closed()
        || std::error::Error::source(e)
            .is_some_and(|s| s.downcast_ref::<std::io::Error>().is_some())
        || e.to_string().contains("timeout")
}

/// A server error told in the lab's words, with what to do next.
pub(crate) fn explain(url: &LabUrl, what: &str, e: postgres::Error) -> StoreError {
    let at = url.shown();
    let user = url.user();
    let msg = match e.code() {
        // Reading (`tribo runs`, `table`, `report` with --catalog) needs SELECT; only a sync writes.
        Some(c) if *c == SqlState::INSUFFICIENT_PRIVILEGE && !what.starts_with("writing") && !what.starts_with("creating") => format!(
            "{what}: the role {user:?} may not read the lab catalog at {at}: a PC that reads it needs \
             a role with SELECT on tribo_runs and tribo_schema (README, \"A catalog for the whole \
             lab\"); ask the catalog's owner for one"
        ),
        Some(c) if *c == SqlState::INSUFFICIENT_PRIVILEGE => format!(
            "{what}: the role {user:?} may not do this in the lab catalog at {at} (nothing was \
             written): a PC that syncs needs a role with INSERT and UPDATE on tribo_runs (README, \
             \"A catalog for the whole lab\"); ask the catalog's owner for one"
        ),
        Some(c) if *c == SqlState::INVALID_PASSWORD || *c == SqlState::INVALID_AUTHORIZATION_SPECIFICATION => format!(
            "{what}: the server at {at} refused the role {user:?}{}: check the role, and its \
             password in PGPASSWORD or the password file (~/.pgpass; on Windows \
             %APPDATA%\\postgresql\\pgpass.conf)",
            match (url.has_password(), url.pgpass_ignored()) {
                (true, _) => String::new(),
                (false, Some(why)) => format!(" (no password: {why})"),
                (false, None) => " (no password was found in PGPASSWORD or the password file)".into(),
            }
        ),
        Some(c) if *c == SqlState::INVALID_CATALOG_NAME => format!(
            "{what}: the server at {at} has no such database: create it (`createdb`, README \"A \
             catalog for the whole lab\") or fix the URL"
        ),
        _ if crate::chain(&e).to_lowercase().contains("certificate") => format!(
            "{what}: the server at {at} showed a TLS certificate this PC does not trust (or that is \
             not for this host name): give the lab's certificate authority with \
             sslrootcert=PATH.pem in the URL, and the server's name as its certificate says"
        ),
        _ if is_transient(&e) => format!(
            "{what}: the lab catalog at {at} cannot be reached or was lost (server down, restarting, \
             or the network cut): check the server and this PC's network; nothing is half-written, \
             run the command again when it is back"
        ),
        // The server asks a password and this PC has none to give (said by the client, before the
        // server could answer): why none was found.
        _ if !url.has_password() && crate::chain(&e).contains("password missing") => format!(
            "{what}: the server at {at} asks a password for the role {user:?} and none was found: {}",
            match url.pgpass_ignored() {
                Some(why) => why.to_string(),
                None => "put it in PGPASSWORD or in the password file (~/.pgpass: \
                         HOST:PORT:DATABASE:USER:PASSWORD, mode 0600, `chmod 600 ~/.pgpass`; on \
                         Windows %APPDATA%\\postgresql\\pgpass.conf)"
                    .to_string(),
            }
        ),
        _ => format!("{what}: the lab catalog at {at} answered with an error"),
    };
    caused(msg, e)
}

fn tls_config(root: &Option<PathBuf>) -> Result<rustls::ClientConfig> {
    use rustls::pki_types::pem::PemObject;
    use rustls::pki_types::CertificateDer;
    let mut roots = rustls::RootCertStore::empty();
    match root {
        Some(p) => {
            let certs: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(p)
                .and_then(|it| it.collect())
                .map_err(|e| {
                    caused(
                        format!(
                            "sslrootcert: cannot read the certificates of {}: give the PEM file of \
                             the lab's certificate authority",
                            p.display()
                        ),
                        e,
                    )
                })?;
            let (added, _) = roots.add_parsable_certificates(certs);
            if added == 0 {
                return Err(err(format!(
                    "sslrootcert: {} holds no usable certificate: give the PEM file of the lab's \
                     certificate authority",
                    p.display()
                )));
            }
        }
        None => roots.extend(webpki_roots::TLS_SERVER_ROOTS.iter().cloned()),
    }
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    Ok(rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| caused("TLS set-up", e))?
        .with_root_certificates(roots)
        .with_no_client_auth())
}

/// Opens a raw connection as `url` says (TLS or not).
pub(crate) fn connect_raw(url: &LabUrl) -> Result<std::result::Result<Client, postgres::Error>> {
    Ok(match &url.tls {
        Tls::Off => url.config.connect(postgres::NoTls),
        Tls::On { root, .. } => {
            let tls = tokio_postgres_rustls::MakeRustlsConnect::new(tls_config(root)?);
            url.config.connect(tls)
        }
    })
}

fn opt_i32(v: Option<u32>) -> Option<i32> {
    v.map(|v| v.min(i32::MAX as u32) as i32)
}

impl LabCatalog {
    /// Connects, and checks the schema: created or migrated when older (needs a role that may
    /// create tables: the catalog's owner, once), refused when newer than this tribo's.
    pub fn connect(url: &LabUrl) -> Result<LabCatalog> {
        let client = connect_raw(url)?.map_err(|e| explain(url, "connecting", e))?;
        let cat = LabCatalog {
            client: RefCell::new(client),
            url: url.clone(),
        };
        cat.migrate()?;
        Ok(cat)
    }

    /// The URL it was reached at.
    pub fn url(&self) -> &LabUrl {
        &self.url
    }

    /// Whether this connection is encrypted (the server's own view: `pg_stat_ssl`).
    pub fn uses_tls(&self) -> Result<bool> {
        let mut c = self.client.borrow_mut();
        c.query_one(
            "SELECT COALESCE((SELECT ssl FROM pg_stat_ssl WHERE pid = pg_backend_pid()), false)",
            &[],
        )
        .map(|r| r.get(0))
        .map_err(|e| explain(&self.url, "reading the connection's state", e))
    }

    /// The schema version the server holds (0: none yet).
    pub fn schema_version(&self) -> Result<i32> {
        let mut c = self.client.borrow_mut();
        read_version(&mut c).map_err(|e| explain(&self.url, "reading the schema version", e))
    }

    fn migrate(&self) -> Result<()> {
        let have = self.schema_version()?;
        if have > VERSION {
            return Err(err(format!(
                "the lab catalog at {} has schema version {have}, newer than this tribo's ({VERSION}): \
                 another PC's newer tribo updated it; update tribo on this PC (nothing was read or written)",
                self.url.shown()
            )));
        }
        if have == VERSION {
            return Ok(());
        }
        let run = || -> std::result::Result<(), postgres::Error> {
            let mut c = self.client.borrow_mut();
            let mut tx = c.transaction()?;
            tx.execute("SELECT pg_advisory_xact_lock($1)", &[&LOCK])?;
            tx.batch_execute(CREATE_VERSION_TABLE)?;
            let have: i32 = tx
                .query_one("SELECT COALESCE(MAX(version), 0) FROM tribo_schema", &[])?
                .get(0);
            for (i, m) in MIGRATIONS.iter().enumerate().skip(have.max(0) as usize) {
                tx.batch_execute(m)?;
                tx.execute(
                    "INSERT INTO tribo_schema (version) VALUES ($1)",
                    &[&(i as i32 + 1)],
                )?;
            }
            tx.commit()
        };
        run().map_err(|e| {
            if e.code() == Some(&SqlState::INSUFFICIENT_PRIVILEGE) {
                err(format!(
                    "the lab catalog at {} is at schema version {have}, this tribo needs {VERSION}, \
                     and the role {:?} may not create tables there: run `tribo sync` (or `tribo runs`) \
                     once as the catalog's owner (README, \"A catalog for the whole lab\")",
                    self.url.shown(),
                    self.url.user()
                ))
            } else {
                explain(&self.url, "creating or updating the catalog's tables", e)
            }
        })?;
        // Another tribo may have raced ahead to a newer version meanwhile: check again.
        let now = self.schema_version()?;
        if now != VERSION {
            return Err(err(format!(
                "the lab catalog at {} is at schema version {now} after migrating to {VERSION}: update tribo on this PC",
                self.url.shown()
            )));
        }
        Ok(())
    }

    /// What the lab knows of the runs of these rigs: `(serial, run number)` → [`Known`].
    pub fn known(&self, serials: &[String]) -> Result<BTreeMap<(String, i64), Known>> {
        let mut c = self.client.borrow_mut();
        let rows = c
            .query(
                "SELECT rig_serial, rig_run, pc, log_dir, pc_stamp, log_bytes FROM tribo_runs \
                 WHERE rig_serial = ANY($1)",
                &[&serials],
            )
            .map_err(|e| explain(&self.url, "reading what the lab catalog holds", e))?;
        Ok(rows
            .into_iter()
            .map(|r| {
                (
                    (r.get(0), r.get(1)),
                    Known {
                        pc: r.get(2),
                        log_dir: r.get(3),
                        pc_stamp: r.get(4),
                        log_bytes: r.get(5),
                    },
                )
            })
            .collect())
    }

    /// Pushes `runs` in one transaction: all of them or none. A run the lab does not have is
    /// added; a run it has is updated when this copy's log is longer, or as long and from the
    /// same PC with something changed (results, label, place); otherwise it is kept (the lab
    /// holds a fuller copy from another PC). Rows are written in key order, so PCs pushing the
    /// same runs at once do not deadlock.
    pub fn push(&self, runs: &[LabRun]) -> Result<PushCounts> {
        self.push_raw(runs)
            .map_err(|e| explain(&self.url, "writing runs to the lab catalog", e))
    }

    /// [`LabCatalog::push`], the server's error as it is (for retries).
    pub fn push_raw(&self, runs: &[LabRun]) -> std::result::Result<PushCounts, postgres::Error> {
        use sha2::Digest;
        let mut order: Vec<&LabRun> = runs.iter().collect();
        order.sort_by(|a, b| (&a.rig_serial, a.rig_run).cmp(&(&b.rig_serial, b.rig_run)));
        let mut c = self.client.borrow_mut();
        let mut tx = c.transaction()?;
        let n = COLUMNS.split(',').count();
        let placeholders: Vec<String> = (1..=n).map(|i| format!("${i}")).collect();
        let updates: Vec<String> = COLUMNS
            .split(',')
            .skip(2)
            .map(|c| format!("{c} = EXCLUDED.{c}"))
            .collect();
        let stmt = tx.prepare(&format!(
            "INSERT INTO tribo_runs ({COLUMNS}) VALUES ({}) ON CONFLICT (rig_serial, rig_run) DO UPDATE SET {}, \
             synced_at = now() WHERE tribo_runs.log_bytes < EXCLUDED.log_bytes OR (tribo_runs.log_bytes = EXCLUDED.log_bytes \
             AND tribo_runs.pc = EXCLUDED.pc AND tribo_runs.row_hash <> EXCLUDED.row_hash) RETURNING (xmax = 0)",
            placeholders.join(","),
            updates.join(", ")
        ))?;
        let mut counts = PushCounts::default();
        for r in order {
            let row_hash = format!("{:x}", sha2::Sha256::digest(format!("{r:?}").as_bytes()));
            let w = &r.row;
            let samples = w.samples as i64;
            let missing = w.missing_blocks as i64;
            let lost = w.lost_samples as i64;
            let blocks = w.blocks as i64;
            let expected = w.blocks_expected.map(|b| b as i64);
            let repeat = opt_i32(w.repeat);
            let cycles = opt_i32(w.cycles);
            let params: [&(dyn ToSql + Sync); 37] = [
                &r.rig_serial,
                &r.rig_run,
                &w.id,
                &r.pc,
                &r.log_dir,
                &r.log_sha256,
                &r.log_bytes,
                &r.pc_stamp,
                &row_hash,
                &w.created,
                &w.status,
                &w.label,
                &w.sample,
                &w.lubricant,
                &w.campaign,
                &repeat,
                &w.load_n,
                &w.temp_c,
                &w.firmware,
                &samples,
                &missing,
                &w.verdict,
                &cycles,
                &w.onboard_mu0,
                &w.onboard_mu1,
                &r.onboard_mu0_se,
                &r.onboard_mu1_se,
                &w.host_mu0,
                &w.host_mu1,
                &w.host_gap,
                &w.host_mu0_se,
                &w.host_mu1_se,
                &lost,
                &blocks,
                &expected,
                &w.completeness,
                &w.temp_setpoint_c,
            ];
            match tx.query_opt(&stmt, &params)? {
                Some(row) if row.get::<_, bool>(0) => counts.inserted += 1,
                Some(_) => counts.updated += 1,
                None => counts.kept += 1,
            }
        }
        tx.commit()?;
        Ok(counts)
    }

    /// Runs matching `f` with where their logs are, oldest first.
    pub fn lab_runs(&self, f: &Filter) -> Result<Vec<LabRow>> {
        f.check()?;
        self.select(
            &format!("{FILTER} ORDER BY created, rig_serial, rig_run"),
            &filter_params(f),
        )
    }

    /// The runs `id` names: a run folder's name, or `SERIAL/RUN` (the rig's serial number and its
    /// run number).
    pub fn find(&self, id: &str) -> Result<Vec<LabRow>> {
        self.select(
            "WHERE run_id = $1 OR rig_serial || '/' || rig_run::text = $1 ORDER BY rig_serial, rig_run",
            &[&id],
        )
    }

    fn select(&self, tail: &str, params: &[&(dyn ToSql + Sync)]) -> Result<Vec<LabRow>> {
        let mut c = self.client.borrow_mut();
        let rows = c
            .query(
                &format!(
                    "SELECT {COLUMNS}, to_char(synced_at AT TIME ZONE 'UTC', 'YYYY-MM-DD\"T\"HH24:MI:SS\"Z\"') FROM tribo_runs {tail}"
                ),
                params,
            )
            .map_err(|e| explain(&self.url, "reading the lab catalog", e))?;
        Ok(rows
            .into_iter()
            .map(|r| {
                let log_dir: String = r.get(4);
                LabRow {
                    run: LabRun {
                        rig_serial: r.get(0),
                        rig_run: r.get(1),
                        pc: r.get(3),
                        log_dir: log_dir.clone(),
                        log_sha256: r.get(5),
                        log_bytes: r.get(6),
                        pc_stamp: r.get(7),
                        onboard_mu0_se: r.get(25),
                        onboard_mu1_se: r.get(26),
                        row: CatalogRow {
                            id: r.get(2),
                            path: PathBuf::from(log_dir),
                            created: r.get(9),
                            status: r.get(10),
                            label: r.get(11),
                            sample: r.get(12),
                            lubricant: r.get(13),
                            campaign: r.get(14),
                            repeat: r.get::<_, Option<i32>>(15).map(|v| v as u32),
                            load_n: r.get(16),
                            temp_c: r.get(17),
                            temp_setpoint_c: r.get(36),
                            firmware: r.get(18),
                            serial: Some(r.get(0)),
                            samples: r.get::<_, i64>(19) as u64,
                            missing_blocks: r.get::<_, i64>(20) as u64,
                            verdict: r.get(21),
                            cycles: r.get::<_, Option<i32>>(22).map(|v| v as u32),
                            onboard_mu0: r.get(23),
                            onboard_mu1: r.get(24),
                            host_mu0: r.get(27),
                            host_mu1: r.get(28),
                            host_gap: r.get(29),
                            host_mu0_se: r.get(30),
                            host_mu1_se: r.get(31),
                            lost_samples: r.get::<_, i64>(32) as u64,
                            blocks: r.get::<_, i64>(33) as u64,
                            blocks_expected: r.get::<_, Option<i64>>(34).map(|v| v as u64),
                            completeness: r.get(35),
                        },
                    },
                    synced_at: r.get(37),
                }
            })
            .collect())
    }
}

fn read_version(c: &mut Client) -> std::result::Result<i32, postgres::Error> {
    let exists: bool = c
        .query_one("SELECT to_regclass('tribo_schema') IS NOT NULL", &[])?
        .get(0);
    if !exists {
        return Ok(0);
    }
    Ok(
        c.query_one("SELECT COALESCE(MAX(version), 0) FROM tribo_schema", &[])?
            .get(0),
    )
}

impl AnyCatalog for LabCatalog {
    fn runs(&self, f: &Filter) -> Result<Vec<CatalogRow>> {
        Ok(self.lab_runs(f)?.into_iter().map(|r| r.run.row).collect())
    }
    fn describe(&self) -> String {
        format!("the lab catalog at {}", self.url.shown())
    }
    /// The campaign table, grouped and averaged by the server (the same groups, mean and sample
    /// standard deviation as [`tribo_store::catalog::tabulate`]), so that a table over a lab's
    /// years of runs does not fetch them all.
    fn table(&self, rows: Axis, cols: Axis, value: Value, f: &Filter) -> Result<Table> {
        let f = table_filter(rows, cols, f)?;
        let v = match value {
            Value::Mu0 => "host_mu0",
            Value::Mu1 => "host_mu1",
            Value::OnboardMu0 => "onboard_mu0",
            Value::OnboardMu1 => "onboard_mu1",
        };
        let (rk, ck) = (bin_key(rows), bin_key(cols));
        let sql = format!(
            "SELECT {rk}, {ck}, avg({v}), stddev_samp({v}), count(*) FROM tribo_runs {FILTER} \
             AND {v} BETWEEN -1e300 AND 1e300 AND {rk} IS NOT NULL AND {ck} IS NOT NULL \
             GROUP BY 1, 2"
        );
        let got = self
            .client
            .borrow_mut()
            .query(&sql, &filter_params(&f))
            .map_err(|e| explain(&self.url, "tabulating the lab catalog", e))?;
        let bin = |a: Axis, k: i64| match a {
            Axis::Load => Bin::LoadMn(k),
            Axis::Temp if k == HEATER_OFF => Bin::HeaterOff,
            Axis::Temp => Bin::SetpointC(k),
        };
        let groups: BTreeMap<(Bin, Bin), Cell> = got
            .iter()
            .map(|r| {
                (
                    (bin(rows, r.get(0)), bin(cols, r.get(1))),
                    Cell {
                        mean: r.get(2),
                        sd: r.get(3),
                        n: r.get::<_, i64>(4) as usize,
                    },
                )
            })
            .collect();
        Ok(Table::of_groups(groups, rows, cols))
    }
}

/// The group key of the heater off on the temperature axis (no setpoint can be this).
const HEATER_OFF: i64 = i64::MIN;

/// A table axis's group key, computed by the server as [`Bin`] is in Rust: loads to the mN and
/// setpoints to the °C, `floor(x + 0.5)` (the same double arithmetic, so the same integers); a run
/// with the heater off is [`HEATER_OFF`]; NULL where the run has no finite value.
fn bin_key(a: Axis) -> String {
    let half_up =
        |x: &str| format!("CASE WHEN {x} BETWEEN -1e15 AND 1e15 THEN floor({x} + 0.5)::bigint END");
    match a {
        Axis::Load => half_up("load_n * 1000"),
        Axis::Temp => format!(
            "(CASE WHEN temp_setpoint_c IS NULL THEN '{HEATER_OFF}'::bigint ELSE {} END)",
            half_up("temp_setpoint_c")
        ),
    }
}
