//! The lab catalog's schema and its versioned migrations.
//!
//! `tribo_schema` holds one row per migration applied. On connecting, a catalog older than this
//! tribo is brought up to date in one transaction, under an advisory lock (two PCs starting at
//! once migrate it once); a catalog newer than this tribo is refused with what to do.

/// The migrations, in order: `MIGRATIONS[i]` takes the schema from version `i` to `i + 1`.
pub const MIGRATIONS: &[&str] = &[
    // 1: the runs, one row per rig serial and rig run number.
    "CREATE TABLE tribo_runs (
        rig_serial TEXT NOT NULL,
        rig_run BIGINT NOT NULL,
        run_id TEXT NOT NULL,
        pc TEXT NOT NULL,
        log_dir TEXT NOT NULL,
        log_sha256 TEXT NOT NULL,
        log_bytes BIGINT NOT NULL,
        pc_stamp TEXT NOT NULL,
        row_hash TEXT NOT NULL,
        created TEXT NOT NULL,
        status TEXT NOT NULL,
        label TEXT,
        sample TEXT,
        lubricant TEXT,
        campaign TEXT,
        repeat INTEGER,
        load_n DOUBLE PRECISION NOT NULL,
        temp_c DOUBLE PRECISION,
        firmware TEXT,
        samples BIGINT NOT NULL,
        missing_blocks BIGINT NOT NULL,
        verdict TEXT,
        cycles INTEGER,
        onboard_mu0 DOUBLE PRECISION,
        onboard_mu1 DOUBLE PRECISION,
        onboard_mu0_se DOUBLE PRECISION,
        onboard_mu1_se DOUBLE PRECISION,
        host_mu0 DOUBLE PRECISION,
        host_mu1 DOUBLE PRECISION,
        host_gap DOUBLE PRECISION,
        host_mu0_se DOUBLE PRECISION,
        host_mu1_se DOUBLE PRECISION,
        lost_samples BIGINT NOT NULL,
        blocks BIGINT NOT NULL,
        blocks_expected BIGINT,
        completeness TEXT NOT NULL,
        synced_at TIMESTAMPTZ NOT NULL DEFAULT now(),
        PRIMARY KEY (rig_serial, rig_run)
    );
    CREATE INDEX tribo_runs_campaign ON tribo_runs (campaign);
    CREATE INDEX tribo_runs_temp ON tribo_runs (temp_c);
    CREATE INDEX tribo_runs_created ON tribo_runs (created);
    CREATE INDEX tribo_runs_run_id ON tribo_runs (run_id);",
    // 2: the heater's setpoint, which tells a heater-off run (NULL) from one held at a setpoint
    // (`temp_c` is the setpoint, else the plate's reading). Rows synced before do not know: they keep
    // their nominal temperature as their setpoint until their PC's next `tribo sync` sends them
    // again (their PC stamp and row hash are cleared so that it does, and the row is replaced).
    "ALTER TABLE tribo_runs ADD COLUMN temp_setpoint_c DOUBLE PRECISION;
    UPDATE tribo_runs SET temp_setpoint_c = temp_c, pc_stamp = '', row_hash = '';",
];

/// The schema version this tribo writes and reads.
pub const VERSION: i32 = MIGRATIONS.len() as i32;

/// The advisory lock taken while migrating (any number, the same for every tribo).
pub(crate) const LOCK: i64 = 0x7472_6962_6f00;

pub(crate) const CREATE_VERSION_TABLE: &str = "CREATE TABLE IF NOT EXISTS tribo_schema (
    version INTEGER PRIMARY KEY,
    applied_at TIMESTAMPTZ NOT NULL DEFAULT now()
)";
