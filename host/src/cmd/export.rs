//! `tribo export`: a run or a record as CSV, JSON or Parquet; with `--catalog`, the catalog's
//! runs and results as one table (the tables and the Parquet writer: [`crate::export`]).

use crate::export::{catalog_csv, catalog_json, catalog_parquet, catalog_rows, Table};
use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use std::path::{Path, PathBuf};
use tribo_store::Filter;

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
    /// Comma-separated values, one row per sample.
    Csv,
    /// One JSON object: the metadata and the columns.
    Json,
    /// Parquet: one typed row per sample, metadata and results in the key-value metadata.
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
            Some(lab) => crate::lab::open_catalog(Some(&lab), &store)?.runs(&Filter::default())?,
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
