//! A run or a record as a table (CSV, JSON or Parquet), and the catalog's runs and results as one
//! table (`tribo export`, the Python package).
//!
//! Parquet is written with the `parquet` crate's low-level writer (no arrow): one row per
//! sample, typed columns whose names carry their unit (`t_s`, `x_m`, …), and the run's metadata,
//! results, gaps and the units in the file's key-value metadata (`tribo.meta`, `tribo.result`,
//! `tribo.gaps`, `tribo.units`, … as JSON), so pandas, polars, DuckDB, R and MATLAB read it
//! as it is. The Python package (`python/`) writes through the same functions.

use anyhow::{bail, Context, Result};
use parquet::basic::{Compression, LogicalType, Repetition, Type as Physical};
use parquet::data_type::{BoolType, ByteArray, ByteArrayType, DoubleType, Int32Type, Int64Type};
use parquet::file::metadata::KeyValue;
use parquet::file::properties::WriterProperties;
use parquet::file::writer::SerializedFileWriter;
use parquet::schema::types::{ColumnPath, Type};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tribo_store::{CatalogRow, Filter, RunCatalog};
/// A column of a table to export.
#[derive(Debug, Clone, PartialEq)]
pub enum Data {
    /// Numbers (Parquet DOUBLE).
    F64(Vec<f64>),
    /// Numbers, some missing (null in JSON, NaN in CSV and Parquet).
    OptF64(Vec<Option<f64>>),
    /// Whole numbers (Parquet INT64).
    I64(Vec<i64>),
    /// Whole numbers, some missing.
    OptI64(Vec<Option<i64>>),
    /// Small whole numbers (Parquet INT32).
    I32(Vec<i32>),
    /// Yes or no.
    Bool(Vec<bool>),
    /// Text.
    Str(Vec<String>),
    /// Text, some missing.
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
        let rec = crate::load::load_record(path)?;
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
    let cat = RunCatalog::open(store)?;
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
    let mut j = run_json(r);
    with_fields(
        &mut j,
        serde_json::json!({
            "sample": r.sample, "lubricant": r.lubricant, "firmware": r.firmware,
            "samples": r.samples, "missing_blocks": r.missing_blocks, "verdict": r.verdict,
            "cycles": r.cycles, "host_gap": r.host_gap,
        }),
    );
    j
}

/// The catalog's rows as one JSON object: `{"runs": [{…}, …]}`.
pub fn catalog_json(rows: &[CatalogRow]) -> serde_json::Value {
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

/// The catalog's rows as CSV, one line per run.
pub fn catalog_csv(rows: &[CatalogRow]) -> String {
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

/// One catalogued run as `tribo runs --json` gives it: the one spelling of a run's row, which the
/// lab catalog's listing, `tribo export --catalog` and the Python package extend.
pub fn run_json(r: &CatalogRow) -> serde_json::Value {
    serde_json::json!({
        "id": r.id, "path": r.path, "created": r.created, "status": r.status,
        "completeness": r.completeness, "blocks": r.blocks,
        "blocks_expected": r.blocks_expected, "lost_samples": r.lost_samples,
        "label": r.label, "campaign": r.campaign, "repeat": r.repeat,
        "load_n": r.load_n, "temp_c": r.temp_c, "temp_setpoint_c": r.temp_setpoint_c,
        "serial": r.serial,
        "onboard_mu0": r.onboard_mu0, "onboard_mu1": r.onboard_mu1,
        "host_mu0": r.host_mu0, "host_mu1": r.host_mu1,
        "host_mu0_se": r.host_mu0_se, "host_mu1_se": r.host_mu1_se,
    })
}

/// `j` (an object) with the fields of `more` (an object) added or replaced.
pub fn with_fields(j: &mut serde_json::Value, more: serde_json::Value) {
    if let (Some(o), serde_json::Value::Object(m)) = (j.as_object_mut(), more) {
        o.extend(m);
    }
}
