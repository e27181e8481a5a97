//! `tribo report RUN|RECORD|CAMPAIGN`: figures (SVG, PNG) and one self-contained HTML page.
//!
//! The work is done by `tribo-report`; this is the glue that tells what the argument names.
use crate::outln;
use anyhow::{bail, Context};
use std::path::{Path, PathBuf};
use tribo_physics::identify::LawSpec;
use tribo_report::{write_record_report, ReportFiles, ReportInputs};
use tribo_store::Filter;

/// Arguments of `tribo report`.
///
/// TARGET is a run folder of the store, a record CSV (`t_s,x_m,v_m_s[,ft_n,temp_c,ecr_ohm]` with
/// `# mass_kg=…` lines), or the name of a campaign in the store's catalog (with `--label`, a
/// substring of the runs' labels). A run gives the figures of one free oscillation; a campaign
/// μ0 and μ1 against the load and the oscillation count against the temperature.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder, record CSV, or campaign name.
    pub target: String,
    /// Output directory (default: `report-<name>` in the current directory).
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// Run store, for a campaign (default: $TRIBO_STORE, else ./runs).
    #[arg(long)]
    pub store: Option<PathBuf>,
    /// A campaign's runs of this rig only (its serial number).
    #[arg(long, value_name = "SERIAL")]
    pub rig: Option<String>,
    /// Only the runs taken in this period.
    #[command(flatten)]
    pub period: super::common::Period,
    /// This PC's catalog of runs, or the lab's.
    #[arg(long, value_name = "URL", help = super::common::CATALOG_HELP)]
    pub catalog: Option<String>,
    /// Select the campaign's runs by label substring instead of campaign name.
    #[arg(long)]
    pub label: bool,
    /// Laws fitted for a run, comma-separated (coulomb, viscous, coulomb-viscous, quadratic,
    /// poly:N, lugre).
    #[arg(
        long,
        default_value = "coulomb,viscous,coulomb-viscous,quadratic",
        value_delimiter = ','
    )]
    pub laws: Vec<LawSpec>,
    /// Write SVG only (no PNG).
    #[arg(long)]
    pub no_png: bool,
}

/// Keeps a name usable as a folder name.
fn clean(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() {
        "report".into()
    } else {
        s
    }
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let path = Path::new(&args.target);
    let laws = args.laws.clone();
    let out_for = |name: &str| {
        args.out
            .clone()
            .unwrap_or_else(|| PathBuf::from(format!("report-{}", clean(name))))
    };
    let mut incomplete = None;
    let files = if path.is_dir() && path.join("meta.toml").is_file() {
        // The one loader: the run, its samples as recorded (a run that is not whole as far as
        // it goes) and the store's warnings about it.
        let opened = crate::load::open(path, crate::Holes::Keep)
            .with_context(|| format!("reading the samples of {}", path.display()))?;
        let (rec, run) = match opened.run {
            Some(run) => (opened.record, run),
            None => bail!("{} is not a run folder", path.display()),
        };
        if !run.is_complete() {
            incomplete = Some(crate::exit::Incomplete(format!(
                "the report of run {} shows what is stored, and the run is {}: `tribo pull {}` fetches the rest \
                 while the rig holds it",
                run.id(),
                run.completeness().summary(),
                path.display()
            )));
        }
        let mut inputs = tribo_report::store::run_inputs(&run);
        inputs.options.laws = laws;
        inputs.options.png = !args.no_png;
        write_record_report(&rec, &inputs, &out_for(run.id()))?
    } else if path.is_file() {
        let rec = crate::analysis::load_for_analysis(path)?;
        let stem = path
            .file_stem()
            .map_or("record".into(), |s| s.to_string_lossy().into_owned());
        let mut inputs = ReportInputs {
            title: format!("Record {}", path.display()),
            meta: vec![("file".into(), path.display().to_string())],
            ..ReportInputs::default()
        };
        inputs.options.laws = laws;
        inputs.options.png = !args.no_png;
        write_record_report(&rec, &inputs, &out_for(&stem))?
    } else if path.is_dir() {
        bail!(
            "{} is a folder but not a run (no meta.toml): give a run folder, a record CSV or a campaign name",
            path.display()
        );
    } else {
        let (files, left) = campaign(&args, &out_for(&args.target))?;
        incomplete = crate::archive::report_left_out("report", &left);
        files
    };
    print_files(&files)?;
    if let Some(e) = incomplete {
        // The report is written, but of an incomplete run: exit status 3.
        return Err(e.into());
    }
    if let Some(why) = &files.not_analysable {
        return Err(crate::exit::Incomplete(format!(
            "{}: not analysable: {why}; the report shows the motion and no fitted constant",
            args.target
        ))
        .into());
    }
    Ok(())
}

/// A campaign's (or a label's) report, and the runs of this PC's store it had to leave out.
fn campaign(
    args: &Args,
    out: &Path,
) -> anyhow::Result<(ReportFiles, Vec<crate::archive::LeftOut>)> {
    args.period.check()?;
    let store = args
        .store
        .clone()
        .unwrap_or_else(tribo_store::default_store_dir);
    let lab = tribo_catalog::lab_url(args.catalog.as_deref()).is_some();
    if !lab && !store.is_dir() {
        bail!(
            "{:?} is neither a run folder, a record file, nor a campaign: there is no run store at {} \
             (point --store at one)",
            args.target,
            store.display()
        );
    }
    let cat = crate::lab::open_catalog(args.catalog.as_deref(), &store)?;
    let filter = args.period.apply(if args.label {
        Filter {
            label: Some(args.target.clone()),
            rig: args.rig.clone(),
            ..Filter::default()
        }
    } else {
        Filter {
            campaign: Some(args.target.clone()),
            rig: args.rig.clone(),
            ..Filter::default()
        }
    });
    let rows = cat.runs(&filter)?;
    let left = if lab {
        Vec::new()
    } else {
        crate::archive::left_out(&store, &filter)?
    };
    if rows.is_empty() && left.is_empty() {
        bail!(
            "no run of {} {:?} in {} (see `tribo runs`; `tribo runs --reindex` rebuilds a PC's own catalog)",
            if args.label { "label" } else { "campaign" },
            args.target,
            cat.describe()
        );
    }
    let title = if args.label {
        format!("Runs labelled {:?}", args.target)
    } else {
        format!("Campaign {}", args.target)
    };
    let points: Vec<_> = rows
        .iter()
        .map(tribo_report::store::campaign_point)
        .collect();
    let inputs = tribo_report::CampaignInputs {
        title,
        png: !args.no_png,
    };
    Ok((
        tribo_report::write_campaign_report(&points, &inputs, out)?,
        left,
    ))
}

fn print_files(files: &ReportFiles) -> std::io::Result<()> {
    outln!("report: {}", files.html.display())?;
    for f in &files.figures {
        match &f.png {
            Some(p) => outln!("  {:<20} {} {}", f.name, f.svg.display(), p.display())?,
            None => outln!("  {:<20} {}", f.name, f.svg.display())?,
        }
    }
    for n in &files.notes {
        outln!("  note: {n}")?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use tribo_physics::integrate::Method;
    use tribo_physics::model::Model;
    use tribo_physics::sensor::{generate, RecordSpec};
    use tribo_physics::{FrictionLaw, Rig};

    fn args(target: &str, out: Option<PathBuf>) -> Args {
        Args {
            target: target.into(),
            out,
            store: None,
            rig: None,
            period: Default::default(),
            catalog: None,
            label: false,
            laws: vec![LawSpec::CoulombViscous],
            no_png: true,
        }
    }

    #[test]
    fn a_record_csv_gets_its_figures_and_page() {
        let dir = std::env::temp_dir().join(format!("tribo-report-cmd-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let spec = RecordSpec {
            rig: Rig::REAL,
            x0_m: 667e-6,
            v0_m_s: 0.0,
            duration_s: 0.5,
            rate_hz: 2000.0,
        };
        let model = Model::new(FrictionLaw::coulomb_viscous(0.02, 0.004));
        let rec = generate(&spec, &model, Method::dopri(1e-9), None).unwrap();
        let csv = dir.join("run.csv");
        rec.save(&csv).unwrap();
        let out = dir.join("out");
        run(args(csv.to_str().unwrap(), Some(out.clone()))).unwrap();
        let html = std::fs::read_to_string(out.join("report.html")).unwrap();
        for f in [
            "motion",
            "envelopes",
            "law",
            "force_velocity",
            "force_displacement",
        ] {
            assert!(out.join(format!("{f}.svg")).is_file(), "{f}");
            assert!(html.contains(&format!("id=\"fig-{f}\"")), "{f}");
        }
        assert!(!out.join("motion.png").exists(), "--no-png");
        // Not a run folder, nor a record, nor a campaign of an existing store.
        let e = run(args(dir.to_str().unwrap(), None))
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a run"), "{e}");
        let mut a = args("no-such-campaign", None);
        a.store = Some(dir.join("no-store"));
        let e = run(a).unwrap_err().to_string();
        assert!(e.contains("no run store"), "{e}");
        assert!("cubic-spline".parse::<LawSpec>().is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
