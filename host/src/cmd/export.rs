//! `tribo export`: a run or a record as CSV, JSON or Parquet; with `--catalog`, the catalog's
//! runs and results as one table.
//!
//! Parquet is written with the `parquet` crate's low-level writer (no arrow): one row per
//! sample, typed columns whose names carry their unit (`t_s`, `x_m`, …), and the run's metadata,
//! results, gaps and the units in the file's key-value metadata (`tribo.meta`, `tribo.result`,
//! `tribo.gaps`, `tribo.units`, … as JSON), so pandas, polars, DuckDB, R and MATLAB read it
//! as it is. The Python package (`python/`) writes through the same functions.

use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use parquet::basic::{Compression, LogicalType, Repetition, Type as Physical};
use parquet::data_type::{BoolType, ByteArray, ByteArrayType, DoubleType, Int32Type, Int64Type};
use parquet::file::metadata::KeyValue;
use parquet::file::properties::WriterProperties;
use parquet::file::writer::SerializedFileWriter;
use parquet::schema::types::{ColumnPath, Type};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tribo_store::{Catalog, CatalogRow, Filter};

/// The long `--help` of the command.
pub const LONG_ABOUT: &str =
    "Write a run or a record as CSV, JSON or Parquet, or the catalog of runs as one table.

SOURCE is a run folder of the store or a record (CSV). The formats:

  csv      the physics record format (`# mass_kg=…` lines, `t_s,x_m,v_m_s[,ft_n,temp_c,ecr_ohm]`):
           what `tribo fit` reads
  json     one object: `metadata` (the Parquet key-value metadata below, its JSON parsed) and
           `columns` (`{\"t_s\": [...], ...}`, null for NaN); for --catalog `{\"runs\": [...]}`
  parquet  one row per sample, typed columns whose names carry their unit: `t_s`, `x_m`,
           `v_m_s`, `ft_n`, `temp_c`, `ecr_ohm` (float64; NaN where the rig had no ECR
           reading), and for a run `sample_index` (int64: jumps across the rig's acquisition
           gaps and blocks not received), `ecr_range` (int32) and `ecr_settling` (bool) when the
           run has them. The key-value metadata holds JSON: `tribo.units` (column → unit),
           `tribo.rig`, and for a run `tribo.meta` (meta.toml), `tribo.result` (the on-board
           result and the host's fit), `tribo.gaps` ([first_sample, count] pairs),
           `tribo.missing_blocks` and `tribo.completeness`. Snappy-compressed.

With `--catalog` (no SOURCE): the runs of the store (`--store`, else $TRIBO_STORE, else ./runs),
one row per run, the columns of `tribo runs --json` plus the run's sample, lubricant, firmware,
samples, missing blocks, on-board verdict, cycles and host gap (nullable where a run has none).
Runs whose log is damaged are not in the catalog: they are named on stderr with how to repair
them, and the export ends with status 3. `--catalog URL` (a PostgreSQL URL, as every other
`--catalog` takes) exports the lab catalog's runs instead; `--catalog` alone takes $TRIBO_CATALOG
when it is set.

Read it back: `pandas.read_parquet(F)`, `polars.read_parquet(F)`,
`duckdb.sql(\"select * from 'F'\")`, R `arrow::read_parquet(F)`, MATLAB `parquetread(F)`; the
metadata with `pyarrow.parquet.read_schema(F).metadata`.";

/// Write a run, a record or the catalog as CSV, JSON or Parquet.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The run folder or record (CSV) to export (not with --catalog).
    #[arg(required_unless_present = "catalog", conflicts_with = "catalog")]
    pub source: Option<PathBuf>,
    /// Output format.
    #[arg(long, value_enum, default_value = "parquet")]
    pub format: Format,
    /// Output file.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Export the catalog of runs (one row per run) instead of one run's samples: with no URL
    /// this PC's store (or $TRIBO_CATALOG when set), with a PostgreSQL URL the lab catalog, as
    /// every other `--catalog` takes it.
    #[arg(long, value_name = "URL", num_args = 0..=1, default_missing_value = "")]
    pub catalog: Option<String>,
    /// Run store directory for --catalog (default: $TRIBO_STORE, else ./runs).
    #[arg(long)]
    pub store: Option<PathBuf>,
    /// No progress messages: set by `tribo -q`/`--quiet`.
    #[arg(skip)]
    pub quiet: bool,
}

/// The formats `tribo export` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Format {
    Csv,
    Json,
    Parquet,
}

/// Runs `tribo export`.
pub fn run(a: Args) -> Result<()> {
    // The run exported is not whole: what it holds is written all the same, and status 3 says so.
    let mut incomplete = None;
    let rows = if let Some(url) = &a.catalog {
        let store = a
            .store
            .clone()
            .unwrap_or_else(tribo_store::default_store_dir);
        let lab = tribo_catalog::lab_url(Some(url.as_str()).filter(|u| !u.is_empty()));
        let rows = match lab {
            Some(lab) => super::sync::open_catalog(Some(&lab), &store)?.runs(&Filter::default())?,
            None => {
                let (rows, damaged) = catalog_rows(&store, &Filter::default(), false)?;
                // The runs the table cannot hold are named, never dropped without a word.
                let left: Vec<crate::archive::LeftOut> = damaged
                    .into_iter()
                    .map(|(dir, why)| crate::archive::LeftOut {
                        why: format!(
                            "damaged ({why}); `tribo pull --salvage {}` keeps every intact record",
                            dir.display()
                        ),
                        dir,
                    })
                    .collect();
                incomplete = crate::archive::report_left_out("export", &left);
                rows
            }
        };
        let n = rows.len();
        match a.format {
            Format::Parquet => catalog_parquet(&rows, &a.output)?,
            Format::Json => write(&a.output, catalog_json(&rows).to_string())?,
            Format::Csv => write(&a.output, catalog_csv(&rows))?,
        }
        n
    } else {
        let Some(src) = a.source.as_deref() else {
            bail!("give a run folder or record to export, or --catalog");
        };
        let t = Table::of_path(src)?;
        let n = t.rows();
        if src.is_dir() {
            if let Ok(run) = tribo_store::Run::open(src) {
                if !run.is_complete() {
                    incomplete = Some(crate::exit::Incomplete(format!(
                        "{}: wrote the {n} samples it holds, and {}",
                        src.display(),
                        crate::load::incomplete_run(&run, src)
                    )));
                }
            }
        }
        match a.format {
            Format::Parquet => t.write_parquet(&a.output)?,
            Format::Json => write(&a.output, t.to_json().to_string())?,
            Format::Csv => {
                // A run's samples without an ECR reading stay empty, as in JSON and Parquet.
                let rec = if src.is_dir() {
                    tribo_store::Run::open(src)
                        .with_context(|| format!("cannot read the run {}", src.display()))?
                        .record_with(false)?
                } else {
                    crate::load::load_record(src)?
                };
                write(&a.output, rec.to_csv_string())?
            }
        }
        n
    };
    if !a.quiet {
        crate::errln!("wrote {rows} rows to {}", a.output.display());
    }
    match incomplete {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}

fn write(path: &Path, text: String) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// A column of a table to export.
#[derive(Debug, Clone, PartialEq)]
pub enum Data {
    F64(Vec<f64>),
    OptF64(Vec<Option<f64>>),
    I64(Vec<i64>),
    OptI64(Vec<Option<i64>>),
    I32(Vec<i32>),
    Bool(Vec<bool>),
    Str(Vec<String>),
    OptStr(Vec<Option<String>>),
}

impl Data {
    fn len(&self) -> usize {
        match self {
            Data::F64(v) => v.len(),
            Data::OptF64(v) => v.len(),
            Data::I64(v) => v.len(),
            Data::OptI64(v) => v.len(),
            Data::I32(v) => v.len(),
            Data::Bool(v) => v.len(),
            Data::Str(v) => v.len(),
            Data::OptStr(v) => v.len(),
        }
    }

    fn to_json(&self) -> serde_json::Value {
        let f =
            |v: f64| serde_json::Number::from_f64(v).map_or(serde_json::Value::Null, Into::into);
        match self {
            Data::F64(v) => v.iter().map(|x| f(*x)).collect(),
            Data::OptF64(v) => v
                .iter()
                .map(|x| x.map_or(serde_json::Value::Null, f))
                .collect(),
            Data::I64(v) => v.iter().copied().collect(),
            Data::OptI64(v) => v.iter().copied().collect(),
            Data::I32(v) => v.iter().copied().collect(),
            Data::Bool(v) => v.iter().copied().collect(),
            Data::Str(v) => v.iter().cloned().collect(),
            Data::OptStr(v) => v.iter().cloned().collect(),
        }
    }
}

/// A table: named columns with their units, and key-value metadata.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Table {
    /// `(name, unit, data)`; the unit is empty for a column without one.
    pub columns: Vec<(String, String, Data)>,
    /// Key-value metadata (JSON values, for `tribo.*` keys).
    pub metadata: Vec<(String, String)>,
}

impl Table {
    fn push(&mut self, name: &str, unit: &str, data: Data) {
        self.columns.push((name.into(), unit.into(), data));
    }

    /// Rows in the table.
    pub fn rows(&self) -> usize {
        self.columns.first().map_or(0, |c| c.2.len())
    }

    /// A run folder's held samples (SI, one row per sample, NaN where the rig had no ECR
    /// reading) or a record's samples, with their metadata.
    pub fn of_path(path: &Path) -> Result<Table> {
        if path.is_dir() {
            let run = tribo_store::Run::open(path)
                .with_context(|| format!("cannot read the run {}", path.display()))?;
            return Table::of_run(&run);
        }
        let rec = tribo_physics::Record::load(path)?;
        Ok(Table::of_record(&rec))
    }

    /// A record's samples.
    pub fn of_record(rec: &tribo_physics::Record) -> Table {
        let mut t = Table::default();
        let si = rec.units == tribo_physics::record::Units::Si;
        if si {
            t.push("t_s", "s", Data::F64(rec.t.clone()));
            t.push("x_m", "m", Data::F64(rec.x.clone()));
            t.push("v_m_s", "m/s", Data::F64(rec.v.clone()));
        } else {
            t.push("tau", "", Data::F64(rec.t.clone()));
            t.push("y", "", Data::F64(rec.x.clone()));
            t.push("ydot", "", Data::F64(rec.v.clone()));
        }
        for (name, unit, col) in [
            ("ft_n", "N", &rec.ft),
            ("temp_c", "°C", &rec.temp),
            ("ecr_ohm", "Ω", &rec.ecr),
        ] {
            if let Some(c) = col {
                t.push(name, unit, Data::F64(c.clone()));
            }
        }
        if let Some(rig) = rec.rig.filter(|_| si) {
            t.metadata.push((
                "tribo.rig".into(),
                serde_json::json!({
                    "mass_kg": rig.mass_kg,
                    "stiffness_n_per_m": rig.stiffness_n_per_m,
                    "load_n": rig.load_n,
                    "force_cutoff_hz": rec.force_cutoff_hz,
                })
                .to_string(),
            ));
        }
        t.finish();
        t
    }

    /// A run's held samples and its metadata.
    pub fn of_run(run: &tribo_store::Run) -> Result<Table> {
        let s = run.samples_si()?;
        let mut t = Table::default();
        t.push("t_s", "s", Data::F64(s.t));
        t.push("x_m", "m", Data::F64(s.x));
        t.push("v_m_s", "m/s", Data::F64(s.v));
        for (name, unit, col) in [
            ("ft_n", "N", s.force),
            ("temp_c", "°C", s.temp_c),
            ("ecr_ohm", "Ω", s.ecr_ohm),
        ] {
            if let Some(c) = col {
                t.push(name, unit, Data::F64(c));
            }
        }
        t.push(
            "sample_index",
            "",
            Data::I64(s.index.iter().map(|&i| i as i64).collect()),
        );
        if let Some(r) = s.ecr_range {
            t.push(
                "ecr_range",
                "",
                Data::I32(r.into_iter().map(i32::from).collect()),
            );
        }
        if let Some(r) = s.ecr_settling {
            t.push("ecr_settling", "", Data::Bool(r));
        }
        let cfg = run.config();
        let gaps: Vec<[u64; 2]> = run
            .gaps()
            .map(|g| [g.first_sample as u64, g.count as u64])
            .collect();
        let md = &mut t.metadata;
        md.push(("tribo.meta".into(), serde_json::to_string(run.meta())?));
        md.push(("tribo.result".into(), serde_json::to_string(&run.results)?));
        md.push(("tribo.gaps".into(), serde_json::to_string(&gaps)?));
        md.push((
            "tribo.missing_blocks".into(),
            serde_json::to_string(&run.missing_blocks())?,
        ));
        md.push(("tribo.completeness".into(), run.completeness().summary()));
        md.push((
            "tribo.rig".into(),
            serde_json::json!({
                "mass_kg": tribo_store::run::clean(cfg.rig.mass_kg),
                "stiffness_n_per_m": tribo_store::run::clean(cfg.rig.stiffness_n_per_m),
                "load_n": tribo_store::run::clean(cfg.rig.load_n),
                "sample_rate_hz": run.clock().rate_hz(),
            })
            .to_string(),
        ));
        t.finish();
        Ok(t)
    }

    /// Adds `tribo.units` (column → unit) to the metadata.
    fn finish(&mut self) {
        let units: serde_json::Map<String, serde_json::Value> = self
            .columns
            .iter()
            .map(|(n, u, _)| (n.clone(), u.clone().into()))
            .collect();
        self.metadata.push((
            "tribo.units".into(),
            serde_json::Value::Object(units).to_string(),
        ));
    }

    /// `{"metadata": {key: parsed JSON or text}, "units": …, "columns": {name: [...]}}`.
    pub fn to_json(&self) -> serde_json::Value {
        let metadata: serde_json::Map<String, serde_json::Value> = self
            .metadata
            .iter()
            .map(|(k, v)| {
                let v = serde_json::from_str(v).unwrap_or_else(|_| v.clone().into());
                (k.clone(), v)
            })
            .collect();
        let columns: serde_json::Map<String, serde_json::Value> = self
            .columns
            .iter()
            .map(|(n, _, d)| (n.clone(), d.to_json()))
            .collect();
        serde_json::json!({ "metadata": metadata, "columns": columns })
    }

    /// Writes the table as Parquet (one row group, Snappy pages).
    pub fn write_parquet(&self, path: &Path) -> Result<()> {
        write_parquet(self, path).with_context(|| format!("writing {}", path.display()))
    }
}

fn field(name: &str, data: &Data) -> Result<Arc<Type>> {
    let (physical, logical, rep) = match data {
        Data::F64(_) => (Physical::DOUBLE, None, Repetition::REQUIRED),
        Data::OptF64(_) => (Physical::DOUBLE, None, Repetition::OPTIONAL),
        Data::I64(_) => (Physical::INT64, None, Repetition::REQUIRED),
        Data::OptI64(_) => (Physical::INT64, None, Repetition::OPTIONAL),
        Data::I32(_) => (Physical::INT32, None, Repetition::REQUIRED),
        Data::Bool(_) => (Physical::BOOLEAN, None, Repetition::REQUIRED),
        Data::Str(_) => (
            Physical::BYTE_ARRAY,
            Some(LogicalType::String),
            Repetition::REQUIRED,
        ),
        Data::OptStr(_) => (
            Physical::BYTE_ARRAY,
            Some(LogicalType::String),
            Repetition::OPTIONAL,
        ),
    };
    Ok(Arc::new(
        Type::primitive_type_builder(name, physical)
            .with_repetition(rep)
            .with_logical_type(logical)
            .build()?,
    ))
}

fn defs<T>(v: &[Option<T>]) -> (Vec<i16>, Vec<&T>) {
    let d = v.iter().map(|x| i16::from(x.is_some())).collect();
    (d, v.iter().flatten().collect())
}

fn write_parquet(t: &Table, path: &Path) -> Result<()> {
    let fields = t
        .columns
        .iter()
        .map(|(n, _, d)| field(n, d))
        .collect::<Result<Vec<_>>>()?;
    let schema = Arc::new(
        Type::group_type_builder("tribo")
            .with_fields(fields)
            .build()?,
    );
    let kv = t
        .metadata
        .iter()
        .map(|(k, v)| KeyValue::new(k.clone(), v.clone()))
        .collect();
    let mut props = WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .set_key_value_metadata(Some(kv))
        .set_created_by(format!("tribo {}", env!("CARGO_PKG_VERSION")));
    // Motion samples are nearly all distinct: a dictionary only costs time before it falls
    // back. The slow channels (temperature, ECR held over a block) and text keep theirs.
    for name in ["t_s", "x_m", "v_m_s", "ft_n", "sample_index"] {
        props = props.set_column_dictionary_enabled(ColumnPath::from(name), false);
    }
    let props = props.build();
    let file = std::fs::File::create(path)?;
    let mut w = SerializedFileWriter::new(file, schema, Arc::new(props))?;
    let mut rg = w.next_row_group()?;
    for (_, _, data) in &t.columns {
        let Some(mut col) = rg.next_column()? else {
            bail!("the Parquet writer has fewer columns than the table");
        };
        match data {
            Data::F64(v) => {
                col.typed::<DoubleType>().write_batch(v, None, None)?;
            }
            Data::OptF64(v) => {
                let (d, vals) = defs(v);
                let vals: Vec<f64> = vals.into_iter().copied().collect();
                col.typed::<DoubleType>()
                    .write_batch(&vals, Some(&d), None)?;
            }
            Data::I64(v) => {
                col.typed::<Int64Type>().write_batch(v, None, None)?;
            }
            Data::OptI64(v) => {
                let (d, vals) = defs(v);
                let vals: Vec<i64> = vals.into_iter().copied().collect();
                col.typed::<Int64Type>()
                    .write_batch(&vals, Some(&d), None)?;
            }
            Data::I32(v) => {
                col.typed::<Int32Type>().write_batch(v, None, None)?;
            }
            Data::Bool(v) => {
                col.typed::<BoolType>().write_batch(v, None, None)?;
            }
            Data::Str(v) => {
                let vals: Vec<ByteArray> = v.iter().map(|s| ByteArray::from(s.as_str())).collect();
                col.typed::<ByteArrayType>()
                    .write_batch(&vals, None, None)?;
            }
            Data::OptStr(v) => {
                let (d, vals) = defs(v);
                let vals: Vec<ByteArray> = vals
                    .into_iter()
                    .map(|s| ByteArray::from(s.as_str()))
                    .collect();
                col.typed::<ByteArrayType>()
                    .write_batch(&vals, Some(&d), None)?;
            }
        }
        col.close()?;
    }
    rg.close()?;
    w.close()?;
    Ok(())
}

/// Run folders the catalog cannot hold (their log is damaged), each with why.
pub type Damaged = Vec<(PathBuf, String)>;

/// The catalog's runs matching `filter` (rebuilding the catalog first when it lags the run
/// folders, as `tribo runs` does, or when `reindex`), and the run folders it cannot hold
/// (their log is damaged) with why.
pub fn catalog_rows(
    store: &Path,
    filter: &Filter,
    reindex: bool,
) -> Result<(Vec<CatalogRow>, Damaged)> {
    if !store.is_dir() {
        bail!(
            "no run store at {}: take a run with `tribo run` or `tribo demo`, or point --store at one",
            store.display()
        );
    }
    filter.check()?;
    let cat = Catalog::open(store)?;
    cat.refresh(reindex)?;
    let folders = tribo_store::run::list_run_dirs(store)?;
    let known: std::collections::BTreeSet<PathBuf> = cat
        .list(&Filter::default())?
        .into_iter()
        .map(|r| r.path)
        .collect();
    let damaged = folders
        .into_iter()
        .filter(|d| !known.contains(d))
        .map(|d| {
            let why = match tribo_store::Run::open(&d) {
                Ok(_) => "not in the catalog: `tribo runs --reindex`".to_string(),
                Err(e) => e.to_string(),
            };
            (d, why)
        })
        .collect();
    Ok((cat.list(filter)?, damaged))
}

/// One catalog row as JSON: the fields of `tribo runs --json` and the rest of the row.
pub fn catalog_row_json(r: &CatalogRow) -> serde_json::Value {
    let mut j = crate::cmd::runs::run_json(r);
    crate::cmd::runs::with_fields(
        &mut j,
        serde_json::json!({
            "sample": r.sample, "lubricant": r.lubricant, "firmware": r.firmware,
            "samples": r.samples, "missing_blocks": r.missing_blocks, "verdict": r.verdict,
            "cycles": r.cycles, "host_gap": r.host_gap,
        }),
    );
    j
}

fn catalog_json(rows: &[CatalogRow]) -> serde_json::Value {
    serde_json::json!({ "runs": rows.iter().map(catalog_row_json).collect::<Vec<_>>() })
}

/// The catalog's rows as a table (the columns of [`catalog_row_json`], in its order).
pub fn catalog_table(rows: &[CatalogRow]) -> Table {
    let mut t = Table::default();
    let s = |f: fn(&CatalogRow) -> String| Data::Str(rows.iter().map(f).collect());
    let os = |f: fn(&CatalogRow) -> Option<String>| Data::OptStr(rows.iter().map(f).collect());
    let of = |f: fn(&CatalogRow) -> Option<f64>| Data::OptF64(rows.iter().map(f).collect());
    let i = |f: fn(&CatalogRow) -> u64| Data::I64(rows.iter().map(|r| f(r) as i64).collect());
    let oi = |f: fn(&CatalogRow) -> Option<u64>| {
        Data::OptI64(rows.iter().map(|r| f(r).map(|v| v as i64)).collect())
    };
    t.push("id", "", s(|r| r.id.clone()));
    t.push("path", "", s(|r| r.path.display().to_string()));
    t.push("created", "", s(|r| r.created.clone()));
    t.push("status", "", s(|r| r.status.clone()));
    t.push("completeness", "", s(|r| r.completeness.clone()));
    t.push("blocks", "", i(|r| r.blocks));
    t.push("blocks_expected", "", oi(|r| r.blocks_expected));
    t.push("lost_samples", "", i(|r| r.lost_samples));
    t.push("label", "", os(|r| r.label.clone()));
    t.push("campaign", "", os(|r| r.campaign.clone()));
    t.push("repeat", "", oi(|r| r.repeat.map(u64::from)));
    t.push(
        "load_n",
        "N",
        Data::F64(rows.iter().map(|r| r.load_n).collect()),
    );
    t.push("temp_c", "°C", of(|r| r.temp_c));
    t.push("temp_setpoint_c", "°C", of(|r| r.temp_setpoint_c));
    t.push("serial", "", os(|r| r.serial.clone()));
    t.push("onboard_mu0", "", of(|r| r.onboard_mu0));
    t.push("onboard_mu1", "", of(|r| r.onboard_mu1));
    t.push("host_mu0", "", of(|r| r.host_mu0));
    t.push("host_mu1", "", of(|r| r.host_mu1));
    t.push("host_mu0_se", "", of(|r| r.host_mu0_se));
    t.push("host_mu1_se", "", of(|r| r.host_mu1_se));
    t.push("sample", "", os(|r| r.sample.clone()));
    t.push("lubricant", "", os(|r| r.lubricant.clone()));
    t.push("firmware", "", os(|r| r.firmware.clone()));
    t.push("samples", "", i(|r| r.samples));
    t.push("missing_blocks", "", i(|r| r.missing_blocks));
    t.push("verdict", "", os(|r| r.verdict.clone()));
    t.push("cycles", "", oi(|r| r.cycles.map(u64::from)));
    t.push("host_gap", "", of(|r| r.host_gap));
    t.finish();
    t
}

/// Writes the catalog's rows as Parquet.
pub fn catalog_parquet(rows: &[CatalogRow], path: &Path) -> Result<()> {
    catalog_table(rows).write_parquet(path)
}

fn catalog_csv(rows: &[CatalogRow]) -> String {
    let t = catalog_table(rows);
    let mut out = t
        .columns
        .iter()
        .map(|c| c.0.as_str())
        .collect::<Vec<_>>()
        .join(",");
    out.push('\n');
    let cell = |v: serde_json::Value| match v {
        serde_json::Value::Null => String::new(),
        serde_json::Value::String(s) if s.contains([',', '"', '\n']) => {
            format!("\"{}\"", s.replace('"', "\"\""))
        }
        serde_json::Value::String(s) => s,
        v => v.to_string(),
    };
    let cols: Vec<Vec<serde_json::Value>> = t
        .columns
        .iter()
        .map(|c| match c.2.to_json() {
            serde_json::Value::Array(a) => a,
            _ => Vec::new(),
        })
        .collect();
    for i in 0..t.rows() {
        let line: Vec<String> = cols.iter().map(|c| cell(c[i].clone())).collect();
        out.push_str(&line.join(","));
        out.push('\n');
    }
    out
}
