//! Test helpers of the host crates, for tests and benchmarks only (a dev-dependency, never a
//! production one): a real PostgreSQL server in a temporary folder ([`PgServer`]), and synthetic
//! runs written through the store as a rig's frames would be ([`synthetic_run`], [`frames`],
//! [`synthetic_store`]).
#![warn(missing_docs)]
//!
//! The server is Debian's PostgreSQL (`/usr/lib/postgresql/*/bin`, or `TRIBO_PG_BIN`, or `initdb`
//! on the PATH): `initdb` and `pg_ctl` in a temporary folder, on a free localhost port, run as the
//! unprivileged `postgres` user when the tests run as root (PostgreSQL refuses root). Without
//! the binaries, [`PgServer::start`] fails and says how to install them, unless
//! `TRIBO_SKIP_POSTGRES=1` says to skip ([`PgServer::skip`]).

use std::path::{Path, PathBuf};
use std::process::Command;
use tribo_store::{DeviceMeta, RunMeta, RunWriter};
use tribo_wire::frame::encode_vec;
use tribo_wire::*;

/// The superuser of a test server and its password (the server asks TCP clients for it).
pub const ADMIN: &str = "tribo_admin";
/// [`ADMIN`]'s password.
pub const ADMIN_PASSWORD: &str = "admin-pw-0";

/// A PostgreSQL server of its own, stopped and deleted when dropped.
pub struct PgServer {
    /// The localhost port it listens on.
    pub port: u16,
    bin: PathBuf,
    data: PathBuf,
    dir: tempfile::TempDir,
    as_user: Option<String>,
    /// More server settings (`-c ssl=on …`), kept across restarts.
    extra: std::cell::RefCell<String>,
}

fn find_bin() -> Option<PathBuf> {
    if let Some(b) = std::env::var_os("TRIBO_PG_BIN") {
        return Some(PathBuf::from(b));
    }
    let mut versions: Vec<PathBuf> = std::fs::read_dir("/usr/lib/postgresql")
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path().join("bin")))
        .filter(|b| b.join("initdb").is_file() && b.join("pg_ctl").is_file())
        .collect();
    versions.sort();
    versions.pop()
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .ok()
        .is_some_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free localhost port")
}

impl PgServer {
    /// Whether the tests that need PostgreSQL are skipped (`TRIBO_SKIP_POSTGRES=1`, for a
    /// developer without it; CI installs it and never sets this).
    pub fn skip() -> bool {
        let skip = std::env::var("TRIBO_SKIP_POSTGRES").is_ok_and(|v| v == "1");
        if skip {
            eprintln!("TRIBO_SKIP_POSTGRES=1: this test of the lab catalog is skipped");
        }
        skip
    }

    /// Creates and starts a server (superuser [`ADMIN`], database `lab`).
    pub fn start() -> PgServer {
        let bin = find_bin().unwrap_or_else(|| {
            panic!(
                "PostgreSQL's server binaries (initdb, pg_ctl) are not installed: \
                 `apt-get install postgresql` (Debian/Ubuntu; `.ci/run` does it), or set TRIBO_PG_BIN \
                 to their folder, or TRIBO_SKIP_POSTGRES=1 to skip the lab catalog's tests"
            )
        });
        let dir = tempfile::Builder::new()
            .prefix("tribo-pg-")
            .tempdir()
            .expect("a temporary folder");
        let as_user = is_root().then(|| "postgres".to_string());
        let data = dir.path().join("data");
        let pwfile = dir.path().join("pw");
        std::fs::write(&pwfile, ADMIN_PASSWORD).unwrap();
        if let Some(u) = &as_user {
            let ok = Command::new("chown")
                .args(["-R", &format!("{u}:"), &dir.path().to_string_lossy()])
                .status()
                .is_ok_and(|s| s.success());
            assert!(
                ok,
                "cannot give {} to the user {u} (PostgreSQL refuses to run as root): create the \
                 user (the postgresql package does) or run the tests as another user",
                dir.path().display()
            );
        }
        let s = PgServer {
            port: free_port(),
            bin,
            data,
            dir,
            as_user,
            extra: Default::default(),
        };
        let out = s
            .cmd("initdb")
            .args([
                "-A",
                "scram-sha-256",
                "-U",
                ADMIN,
                "-E",
                "UTF8",
                "--no-sync",
            ])
            .arg("--pwfile")
            .arg(&pwfile)
            .arg("-D")
            .arg(&s.data)
            .output()
            .expect("initdb runs");
        assert!(
            out.status.success(),
            "initdb failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        s.start_again();
        s.psql("postgres", "CREATE DATABASE lab");
        s
    }

    fn cmd(&self, tool: &str) -> Command {
        let exe = self.bin.join(tool);
        match &self.as_user {
            Some(u) => {
                let mut c = Command::new("runuser");
                c.args(["-u", u, "--"]).arg(exe);
                c
            }
            None => Command::new(exe),
        }
    }

    /// Starts the (stopped) server again on the same port.
    pub fn start_again(&self) {
        let opts = format!(
            "-p {} -k {} -c listen_addresses=127.0.0.1 -c fsync=off -c max_connections=60 {}",
            self.port,
            self.dir.path().display(),
            self.extra.borrow()
        );
        // Wait for a port freed by a stop to be bound again.
        for attempt in 0.. {
            let out = self
                .cmd("pg_ctl")
                .arg("-D")
                .arg(&self.data)
                .args(["-w", "-t", "30", "-o", &opts, "-l"])
                .arg(self.dir.path().join("log"))
                .arg("start")
                .output()
                .expect("pg_ctl runs");
            if out.status.success() {
                return;
            }
            if attempt == 20 {
                panic!(
                    "pg_ctl start failed: {}{}",
                    String::from_utf8_lossy(&out.stderr),
                    std::fs::read_to_string(self.dir.path().join("log")).unwrap_or_default()
                );
            }
            std::thread::sleep(std::time::Duration::from_millis(250));
        }
    }

    /// Stops the server (`fast`: connections are cut, as a crash or a restart cuts them).
    pub fn stop(&self) {
        let _ = self
            .cmd("pg_ctl")
            .arg("-D")
            .arg(&self.data)
            .args(["-w", "-m", "fast", "stop"])
            .output();
    }

    /// Restarts the server with TLS on: a certificate authority and a certificate for
    /// `localhost` and 127.0.0.1 signed by it (made with the `openssl` command). Returns the
    /// authority's PEM file (what `sslrootcert=` takes).
    pub fn enable_tls(&self) -> PathBuf {
        let d = self.dir.path();
        let ext = d.join("ext.cnf");
        std::fs::write(
            &ext,
            "basicConstraints=CA:FALSE\nsubjectAltName=DNS:localhost,IP:127.0.0.1\n",
        )
        .unwrap();
        let s = |p: &str| d.join(p).to_string_lossy().into_owned();
        for args in [
            vec![
                "req",
                "-x509",
                "-newkey",
                "rsa:2048",
                "-nodes",
                "-days",
                "2",
                "-subj",
                "/CN=tribo test CA",
                "-keyout",
                &s("ca.key"),
                "-out",
                &s("ca.pem"),
                "-addext",
                "basicConstraints=critical,CA:TRUE",
                "-addext",
                "keyUsage=critical,keyCertSign,cRLSign",
            ],
            vec![
                "req",
                "-newkey",
                "rsa:2048",
                "-nodes",
                "-subj",
                "/CN=localhost",
                "-keyout",
                &s("server.key"),
                "-out",
                &s("server.csr"),
            ],
            vec![
                "x509",
                "-req",
                "-in",
                &s("server.csr"),
                "-CA",
                &s("ca.pem"),
                "-CAkey",
                &s("ca.key"),
                "-CAcreateserial",
                "-days",
                "2",
                "-extfile",
                &s("ext.cnf"),
                "-out",
                &s("server.pem"),
            ],
        ] {
            let out = Command::new("openssl")
                .args(&args)
                .output()
                .expect("the openssl command (Debian package openssl, a dependency of postgresql)");
            assert!(
                out.status.success(),
                "openssl {args:?}: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        let key = d.join("server.key");
        #[cfg(unix)]
        {
            let mut perm = std::fs::metadata(&key).unwrap().permissions();
            std::os::unix::fs::PermissionsExt::set_mode(&mut perm, 0o600);
            std::fs::set_permissions(&key, perm).unwrap();
        }
        if let Some(u) = &self.as_user {
            let _ = Command::new("chown")
                .arg(format!("{u}:"))
                .arg(&key)
                .arg(d.join("server.pem"))
                .status();
        }
        *self.extra.borrow_mut() = format!(
            "-c ssl=on -c ssl_cert_file={} -c ssl_key_file={}",
            s("server.pem"),
            s("server.key")
        );
        self.stop();
        self.start_again();
        d.join("ca.pem")
    }

    /// Runs SQL as the superuser through `psql` on the server's socket; panics on failure.
    pub fn psql(&self, db: &str, sql: &str) -> String {
        let psql = ["psql", "/usr/bin/psql"]
            .into_iter()
            .map(|p| self.bin.join(p))
            .find(|p| p.is_file())
            .unwrap_or_else(|| PathBuf::from("psql"));
        let out = Command::new(psql)
            .args([
                "-X",
                "-q",
                "-t",
                "-A",
                "-v",
                "ON_ERROR_STOP=1",
                "-h",
                "127.0.0.1",
            ])
            .args([
                "-p",
                &self.port.to_string(),
                "-U",
                ADMIN,
                "-d",
                db,
                "-c",
                sql,
            ])
            .env("PGPASSWORD", ADMIN_PASSWORD)
            .output()
            .expect("psql runs");
        assert!(
            out.status.success(),
            "psql {sql:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).trim().to_string()
    }

    /// The URL of database `db` as `user` (no password in it).
    pub fn url(&self, user: &str, db: &str) -> String {
        format!("postgres://{user}@127.0.0.1:{}/{db}", self.port)
    }

    /// A [`tribo_catalog::LabUrl`] of database `db` as `user` with `password`, read from no environment
    /// but this.
    pub fn lab_url(&self, user: &str, password: &str, db: &str) -> tribo_catalog::LabUrl {
        let pw = password.to_string();
        tribo_catalog::LabUrl::parse_with(&self.url(user, db), &move |k| {
            (k == "PGPASSWORD").then(|| pw.clone())
        })
        .expect("the test server's URL")
    }

    /// The admin's [`tribo_catalog::LabUrl`] of database `lab`.
    pub fn admin(&self) -> tribo_catalog::LabUrl {
        self.lab_url(ADMIN, ADMIN_PASSWORD, "lab")
    }

    /// The server's log.
    pub fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("log")).unwrap_or_default()
    }

    /// The temporary folder that holds its data, deleted when it is dropped.
    pub fn folder(&self) -> &Path {
        self.dir.path()
    }
}

impl PgServer {
    /// How many runs the lab catalog in database `lab` holds.
    pub fn run_count(&self) -> usize {
        self.psql("lab", "SELECT count(*) FROM tribo_runs")
            .parse()
            .expect("a count of runs")
    }
}

impl Drop for PgServer {
    fn drop(&mut self) {
        let _ = self
            .cmd("pg_ctl")
            .arg("-D")
            .arg(&self.data)
            .args(["-w", "-m", "immediate", "stop"])
            .output();
    }
}

/// Writes a synthetic complete run of rig `serial`, its run number `run_no`, into `store`
/// through [`RunWriter`] (as `tribo run` files a rig's frames): `nblocks` blocks of a decaying
/// sine, an on-board result with `mu0`, the end.
pub fn synthetic_run(
    store: &Path,
    serial: &str,
    run_no: u32,
    nblocks: u32,
    mu0: f32,
    meta_fn: impl FnOnce(&mut RunMeta),
) -> tribo_store::Run {
    let cfg = Configure::real_rig(0.3);
    let mut meta = RunMeta::new(cfg);
    meta.device = Some(DeviceMeta {
        firmware: "0.1.0".into(),
        serial: serial.into(),
        protocol: PROTOCOL_VERSION,
        port: "tcp://127.0.0.1:7411".into(),
    });
    meta_fn(&mut meta);
    let mut w = RunWriter::create(store, meta).expect("a run folder");
    for f in frames(&cfg, run_no, nblocks, 0, nblocks, mu0) {
        w.append_frame(&f).expect("a frame filed");
    }
    w.finish(false).expect("the run finished")
}

/// The frames of a synthetic run: its header, blocks `from..to` of `nblocks`, and (when `to ==
/// nblocks`) its result and end.
pub fn frames(
    cfg: &Configure,
    run_no: u32,
    nblocks: u32,
    from: u32,
    to: u32,
    mu0: f32,
) -> Vec<Vec<u8>> {
    let w = cfg.omega() as f64;
    let rate = cfg.sample_rate_hz as f64;
    let mut out = vec![];
    let mut seq = from * 2;
    let mut push = |m: DeviceMsg| {
        seq += 1;
        out.push(encode_vec(seq, &m).expect("a frame"));
    };
    push(DeviceMsg::RunStarted(RunHeader {
        run_id: run_no,
        config: *cfg,
        temp_c: 41.5,
        t_us: 1000,
        clock: SampleClock {
            timer_hz: 200_000_000,
            ticks_per_sample: 200_000_000 / cfg.sample_rate_hz,
        },
    }));
    for b in from..to {
        let mut counts = Counts::default();
        for i in 0..BLOCK_LEN {
            let t = (b as usize * BLOCK_LEN + i) as f64 / rate;
            let x = cfg.initial_amplitude_m as f64 * (-t).exp() * (w * t).cos();
            let v = -cfg.initial_amplitude_m as f64 * w * (-t).exp() * (w * t).sin();
            let vals = [x, v, 0.01 * v.signum(), 1.0, 41.5];
            for c in cfg.channels.iter() {
                let _ = counts.push(cfg.calibration[c.index()].to_count(vals[c.index()] as f32));
            }
        }
        push(DeviceMsg::Samples(SampleBlock {
            run_id: run_no,
            block: b,
            first_sample: b * BLOCK_LEN as u32,
            t_us: 1000 + (b as u64 * BLOCK_LEN as u64 * 100),
            channels: cfg.channels,
            ecr_range: 2,
            log10_ecr_ohm: 6.5,
            temp_c: 41.5,
            counts,
        }));
    }
    if to == nblocks {
        let est = Estimate {
            mu0,
            mu1: 0.01,
            mu0_se: 0.0001,
            mu1_se: 0.00002,
        };
        push(DeviceMsg::Result(OnboardResult {
            run_id: run_no,
            verdict: Verdict::Ok,
            cycles: 12,
            frequency_hz: 26.9,
            initial_amplitude_m: cfg.initial_amplitude_m,
            duration_s: 1.0,
            best: est,
            averaging: est,
            decrement: est,
            shape: EnvelopeShape::Straight,
            curvature: 0.0,
        }));
        push(DeviceMsg::RunEnded(RunEnd {
            run_id: run_no,
            blocks: nblocks,
            samples: nblocks * BLOCK_LEN as u32,
            overruns: 0,
            reason: EndReason::Stopped,
        }));
    }
    out
}

/// A store of `n` synthetic runs of rig `serial` ([`synthetic_run`], two blocks each), run
/// numbers from `first`: the `i`-th (from 0) with on-board μ0 `mu0(i)`, described by
/// `meta_fn(i, meta)`.
pub fn synthetic_store(
    store: &Path,
    serial: &str,
    first: u32,
    n: u32,
    mu0: impl Fn(u32) -> f32,
    meta_fn: impl Fn(u32, &mut RunMeta),
) {
    for i in 0..n {
        synthetic_run(store, serial, first + i, 2, mu0(i), |m| meta_fn(i, m));
    }
}
