//! Honest answers from the command line: records that cannot be analysed, strict inputs, usage
//! errors, closed pipes, `-q`, the rig constants that defaults stood in for, and advice that names
//! flags which exist. Exit statuses as documented (0 ok, 1 error, 2 usage, 3 incomplete).

use crate::support::tribo;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use tribo_physics::integrate::Method;
use tribo_physics::sensor::{generate, RecordSpec, SensorModel};
use tribo_physics::{FrictionLaw, Model, Record, Rig};

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

struct Dir(PathBuf);
impl Dir {
    fn new(name: &str) -> Dir {
        let d =
            std::env::temp_dir().join(format!("tribo-cli-honest-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        Dir(d)
    }
    fn path(&self, f: &str) -> PathBuf {
        self.0.join(f)
    }
}
impl Drop for Dir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn record(law: FrictionLaw, duration_s: f64, noise: bool) -> Record {
    let spec = RecordSpec {
        rig: Rig::REAL,
        x0_m: 667e-6,
        v0_m_s: 0.0,
        duration_s,
        rate_hz: 10_000.0,
    };
    let s = SensorModel::default();
    generate(
        &spec,
        &Model::new(law),
        Method::dopri(1e-9),
        noise.then_some(&s),
    )
    .unwrap()
}

fn write(p: &Path, rec: &Record) -> String {
    rec.save(p).unwrap();
    p.to_str().unwrap().to_string()
}

/// The records that cannot be analysed, with what the message must say.
fn not_analysable(d: &Dir) -> Vec<(String, &'static str)> {
    let mut out = Vec::new();
    let good = record(FrictionLaw::coulomb_viscous(0.02, 0.01), 1.0, true);
    // The pin never moves.
    let mut flat = good.clone();
    flat.x.iter_mut().for_each(|x| *x = 1e-5);
    flat.v.iter_mut().for_each(|v| *v = 0.0);
    out.push((write(&d.path("flat.csv"), &flat), "no oscillation"));
    // Pure noise: the vibrometer's noise and nothing else.
    let mut noise = good.clone();
    let mut rng = tribo_physics::sensor::Rng::new(3);
    noise.x.iter_mut().for_each(|x| *x = 2e-8 * rng.normal());
    noise.v.iter_mut().for_each(|v| *v = 2e-5 * rng.normal());
    out.push((write(&d.path("noise.csv"), &noise), "no oscillation"));
    // Coulomb friction so high that the pin stops after a half cycle or two.
    let short = record(FrictionLaw::coulomb(0.8), 1.0, true);
    out.push((write(&d.path("short.csv"), &short), "too few half cycles"));
    // A displacement converter whose range is too small: clipped at 80 % of x0.
    let mut sat = good.clone();
    let lim = 0.8 * 667e-6;
    sat.x.iter_mut().for_each(|x| *x = x.clamp(-lim, lim));
    out.push((write(&d.path("saturated.csv"), &sat), "saturated"));
    // An infinite value in the middle of the file.
    let p = d.path("inf.csv");
    write(&p, &good);
    let t = std::fs::read_to_string(&p).unwrap();
    let mut lines: Vec<String> = t.lines().map(String::from).collect();
    let f: Vec<&str> = lines[500].split(',').collect();
    lines[500] = format!("{},inf,{}", f[0], f[2..].join(","));
    std::fs::write(&p, lines.join("\n") + "\n").unwrap();
    out.push((p.to_str().unwrap().to_string(), "line 501, column"));
    out
}

#[test]
fn records_that_cannot_be_analysed_exit_3_without_coefficients() {
    let d = Dir::new("na");
    for (rec, why) in not_analysable(&d) {
        for args in [
            vec!["fit", rec.as_str()],
            vec!["fit", rec.as_str(), "--law", "quadratic"],
            vec!["explain", rec.as_str()],
            vec!["onboard", rec.as_str()],
        ] {
            let o = tribo(&args);
            let (out, err) = (text(&o.stdout), text(&o.stderr));
            assert_eq!(o.status.code(), Some(3), "{args:?}: {out}\n{err}");
            assert!(!out.contains("mu0"), "{args:?} printed constants: {out}");
            assert!(!err.contains("panicked"), "{args:?}: {err}");
            if args[0] != "onboard" || why.starts_with("line") {
                assert!(err.contains(why), "{args:?}: {err} (want {why:?})");
            }
            assert!(!out.contains("converged"), "{args:?}: {out}");
        }
        // JSON says why in one object, whatever the command and wherever the record was refused
        // (a non-finite sample is refused as the file is read), and has no constant either.
        for cmd in ["fit", "explain"] {
            let o = tribo(&[cmd, rec.as_str(), "--json"]);
            assert_eq!(o.status.code(), Some(3));
            let out = text(&o.stdout);
            assert_eq!(out.trim().lines().count(), 1, "{cmd}: {out}");
            let v: serde_json::Value = serde_json::from_str(out.trim())
                .unwrap_or_else(|e| panic!("{cmd} --json: {e}: {out:?}"));
            assert_eq!(v["verdict"], "not-analysable", "{v}");
            assert!(v.get("mu").is_none(), "{v}");
            assert!(v["message"].as_str().unwrap().contains(why), "{v}");
        }
        let o = tribo(&["onboard", rec.as_str(), "--json"]);
        assert_eq!(o.status.code(), Some(3));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert!(v.get("mu0").is_none_or(|m| m.is_null()), "{v}");
        // The report draws the motion (nothing is lost) but fits nothing.
        if !why.starts_with("line") {
            let out = d.path("report");
            let o = tribo(&[
                "report",
                rec.as_str(),
                "--no-png",
                "--laws",
                "coulomb-viscous",
                "-o",
                out.to_str().unwrap(),
            ]);
            assert_eq!(o.status.code(), Some(3), "{}", text(&o.stderr));
            assert!(out.join("motion.svg").is_file());
            let html = std::fs::read_to_string(out.join("report.html")).unwrap();
            assert!(html.contains("not analysable") && !html.contains("host fit:"));
        }
    }
}

#[test]
fn fit_prints_standard_errors_noise_floor_and_verdict() {
    let d = Dir::new("fit");
    let rec = write(
        &d.path("cv.csv"),
        &record(FrictionLaw::coulomb_viscous(0.02, 0.01), 1.0, true),
    );
    let o = tribo(&["fit", &rec]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    for want in [
        "±",
        "noise floor",
        "verdict    converged and adequate",
        "half cycles",
    ] {
        assert!(out.contains(want), "{want:?} missing:\n{out}");
    }
    // The quadratic record fitted with the Coulomb–viscous law: converged but inadequate, with
    // the advice to run explain; still status 0 (the answer is complete).
    let q = write(
        &d.path("q.csv"),
        &record(FrictionLaw::quadratic(0.02, 0.004, 0.004), 1.0, true),
    );
    let o = tribo(&["fit", &q]);
    assert_eq!(o.status.code(), Some(0));
    let out = text(&o.stdout);
    assert!(
        out.contains("inadequate") && out.contains("tribo explain"),
        "{out}"
    );
}

#[test]
fn strict_record_parsing() {
    let d = Dir::new("strict");
    let good = record(FrictionLaw::coulomb_viscous(0.02, 0.01), 1.0, true).to_csv_string();
    let run = |name: &str, body: &[u8]| -> Output {
        let p = d.path(name);
        std::fs::write(&p, body).unwrap();
        tribo(&["fit", p.to_str().unwrap()])
    };
    // A constant given twice: an error naming both lines.
    let twice = format!("# load_n=0.25\n{good}");
    let o = run("twice.csv", twice.as_bytes());
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("twice.csv") && err.contains("line 4") && err.contains("first on line 1"),
        "{err}"
    );
    // A UTF-8 byte-order mark is fine.
    let bom = [&b"\xef\xbb\xbf"[..], good.as_bytes()].concat();
    let o = run("bom.csv", &bom);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    // A byte that is not UTF-8: the file, line and column.
    let mut bad = good.clone().into_bytes();
    let line5 = bad
        .iter()
        .enumerate()
        .filter(|(_, b)| **b == b'\n')
        .nth(5)
        .unwrap()
        .0;
    bad[line5 + 3] = 0xff;
    let o = run("latin.csv", &bad);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("latin.csv") && err.contains("line 7, column 3") && err.contains("UTF-8"),
        "{err}"
    );
    // A field that is not a number: line and column.
    let garbage = good.replacen("\n0e0,", "\n0e0,x", 1);
    let o = run("garbage.csv", garbage.as_bytes());
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("line 6, column 5") && err.contains("not a number"),
        "{err}"
    );
    // A column named twice.
    let dup = good.replacen("t_s,x_m,v_m_s,ft_n", "t_s,x_m,v_m_s,x_m", 1);
    let o = run("dup.csv", dup.as_bytes());
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("appears twice") && err.contains("line 5, column 15"),
        "{err}"
    );
}

#[test]
fn defaults_that_stand_in_for_rig_constants_are_recorded() {
    let d = Dir::new("defaults");
    let mut rec = record(FrictionLaw::coulomb_viscous(0.02, 0.01), 1.0, true);
    rec.rig = None;
    let p = write(&d.path("bare.csv"), &rec);
    // No constants and no flag: an error that says which flags to pass.
    let o = tribo(&["fit", &p]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o.stderr).contains("--load-n"), "{}", text(&o.stderr));
    // The load from a flag, mass and stiffness from the real rig's defaults: said so.
    let o = tribo(&["fit", &p, "--load-n", "0.3", "--json"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        v["defaults"],
        serde_json::json!(["mass_kg", "stiffness_n_per_m"])
    );
    assert_eq!(v["rig"]["load_n_from"], "flag");
    assert_eq!(v["rig"]["mass_kg_from"], "default");
    let o = tribo(&["fit", &p, "--load-n", "0.3"]);
    let out = text(&o.stdout);
    assert!(
        out.contains("DEFAULT") && out.contains("stood in for mass_kg, stiffness_n_per_m"),
        "{out}"
    );
}

#[test]
fn usage_errors_exit_2() {
    for args in [
        vec!["run", "--load", "0.3", "--repeat", "0"],
        vec!["runs", "--status", "finished"],
        vec!["runs", "--load", "heavy"],
        vec!["runs", "--temp", "60..25"],
        vec!["table", "--rows", "humidity"],
        vec!["table", "--value", "mu7"],
        vec!["table", "--since", "2026-13-01"],
        vec!["table", "--since", "2026-02-01", "--until", "2026-01-31"],
        vec![
            "report",
            "some-campaign",
            "--since",
            "2026-02-01",
            "--until",
            "2026-01-31",
        ],
        vec!["fit", "x.csv", "--law", "cubic-banana"],
        vec!["explain", "x.csv", "--only", "magic"],
        vec!["explain", "x.csv", "--base", "lugre"],
        vec!["report", "x.csv", "--laws", "spline"],
    ] {
        let o = tribo(&args);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

/// A value clap takes but the rig would refuse is caught before anything is sent: status 2, and
/// the message names the flag and the range the rig accepts.
#[test]
fn out_of_range_run_settings_are_usage_errors_naming_flag_and_range() {
    for (args, says) in [
        (vec!["--load", "0.9"], "--load: the load (0–0.7 N)"),
        (
            vec!["--load", "0.3", "--rate", "50000"],
            "--rate: the sample rate (1–20 kHz)",
        ),
        (
            vec!["--load", "0.3", "--max-duration", "90"],
            "--max-duration: the maximum duration (0.1–60 s)",
        ),
        (
            vec!["--load", "0.3", "--temp", "120"],
            "the heater setpoint (15–100 °C)",
        ),
        (
            vec!["--load", "0.3", "--temp", "40", "--ramp", "0"],
            "the heater ramp (0.1–30 °C/min)",
        ),
        (vec!["--load", "NaN"], "--load: the load"),
    ] {
        // A port nobody listens on: reaching it would be status 1, not 2.
        let mut all = vec!["run", "--port", "tcp://127.0.0.1:1"];
        all.extend(&args);
        let o = tribo(&all);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
        assert!(err.contains("out of the rig's range"), "{args:?}: {err}");
    }
}

/// Runs `tribo args` with its standard output a pipe whose reader is already closed.
fn into_closed_pipe(args: &[&str]) -> Output {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let child = Command::new(crate::support::TRIBO)
        .args(args)
        .stdin(Stdio::null())
        .stdout(writer)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child.wait_with_output().unwrap()
}

#[test]
fn closed_pipes_end_quietly() {
    let d = Dir::new("pipe");
    let rec = write(
        &d.path("cv.csv"),
        &record(FrictionLaw::coulomb_viscous(0.02, 0.01), 1.0, true),
    );
    let store = d.path("store");
    std::fs::create_dir_all(&store).unwrap();
    let store = store.to_str().unwrap().to_string();
    let report = d.path("report");
    let report = report.to_str().unwrap().to_string();
    for args in [
        vec!["--help"],
        vec!["fit", "--help"],
        vec!["fit", &rec],
        vec!["fit", &rec, "--json", "--windows", "2"],
        vec!["onboard", &rec],
        vec!["onboard", &rec, "--json"],
        vec!["explain", &rec, "--json", "--max-steps", "0"],
        vec!["runs", "--store", &store],
        vec!["table", "--store", &store],
        vec!["report", &rec, "--no-png", "-o", &report],
        vec!["devices"],
    ] {
        let o = into_closed_pipe(&args);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(0), "{args:?}: {err}");
        assert!(
            !err.contains("panicked") && !err.contains("Broken pipe"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn quiet_silences_progress() {
    let d = Dir::new("quiet");
    let out = d.path("rec.csv");
    let out = out.to_str().unwrap();
    let loud = tribo(&["sim", "--duration-s", "0.2", "-o", out]);
    assert!(text(&loud.stderr).contains("wrote"), "the message exists");
    for args in [
        vec!["-q", "sim", "--duration-s", "0.2", "-o", out],
        vec!["sim", "--duration-s", "0.2", "-o", out, "--quiet"],
    ] {
        let o = tribo(&args);
        assert_eq!(o.status.code(), Some(0));
        assert_eq!(text(&o.stderr), "", "{args:?}");
    }
    let store = d.path("store");
    std::fs::create_dir_all(store.join("2024-01-01T000000Z-stray")).unwrap();
    let o = tribo(&[
        "-q",
        "runs",
        "--store",
        store.to_str().unwrap(),
        "--reindex",
    ]);
    assert!(
        !text(&o.stderr).contains("catalog rebuilt"),
        "{}",
        text(&o.stderr)
    );
}

/// Every `--flag` that the sources mention in a message, an advice or a help text is a flag that
/// `tribo` knows (of some subcommand, or global). Flags are collected from the `--help` of every
/// subcommand; mentions from every string literal and doc comment of the host crates.
#[test]
fn every_flag_named_in_advice_exists() {
    let top = text(&tribo(&["--help"]).stdout);
    let mut known: std::collections::BTreeSet<String> = flags_in(&top).into_iter().collect();
    let subs: Vec<String> = top
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next().map(String::from))
        .filter(|s| s != "help")
        .collect();
    assert!(subs.len() >= 10, "{subs:?}");
    for s in &subs {
        known.extend(flags_in(&text(&tribo(&[s, "--help"]).stdout)));
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for dir in [
        "src",
        "physics/src",
        "explain/src",
        "report/src",
        "rig/src",
        "store/src",
    ] {
        collect_rs(&root.join(dir), &mut files);
    }
    let mut unknown = Vec::new();
    let mut seen = 0;
    for f in &files {
        let src = std::fs::read_to_string(f).unwrap();
        for (line, relevant) in strings_and_docs(&src) {
            for flag in flags_in(&relevant) {
                seen += 1;
                if !known.contains(&flag) && !NOT_TRIBO.contains(&flag.as_str()) {
                    unknown.push(format!("{}:{line}: {flag}", f.display()));
                }
            }
        }
    }
    assert!(
        seen > 30,
        "only {seen} flag mentions found: is the scan working?"
    );
    assert!(
        unknown.is_empty(),
        "flags that tribo does not know:\n{}",
        unknown.join("\n")
    );
}

/// Flags of other programs that the sources name on purpose.
const NOT_TRIBO: &[&str] = &[
    // cargo and its test harness
    "--release",
    "--all",
    "--check",
    "--example",
    "--bin",
    "--test",
    "--nocapture",
    "--ignored",
];

fn flags_in(s: &str) -> Vec<String> {
    let b = s.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i + 2 < b.len() {
        let boundary = i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'-');
        if boundary && b[i] == b'-' && b[i + 1] == b'-' && b[i + 2].is_ascii_lowercase() {
            let mut j = i + 2;
            while j < b.len()
                && (b[j].is_ascii_lowercase() || b[j].is_ascii_digit() || b[j] == b'-')
            {
                j += 1;
            }
            out.push(s[i..j].trim_end_matches('-').to_string());
            i = j;
        } else {
            i += 1;
        }
    }
    out
}

/// The string literals and doc comments of Rust source, with the line each starts on: where
/// messages, advice and help texts live (not code, nor `//` notes). A small lexer: it knows char
/// literals (`'"'`), lifetimes, escapes, raw strings and block comments.
fn strings_and_docs(src: &str) -> Vec<(usize, String)> {
    let c: Vec<char> = src.chars().collect();
    let (mut i, mut line, mut out) = (0usize, 1usize, Vec::new());
    let ident = |ch: char| ch.is_alphanumeric() || ch == '_';
    while i < c.len() {
        let at = |k: usize| c.get(i + k).copied().unwrap_or('\0');
        let next = at(1);
        if c[i] == '\n' {
            line += 1;
            i += 1;
        } else if c[i] == '/' && next == '/' {
            let start = i;
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
            let t: String = c[start..i].iter().collect();
            if t.starts_with("///") || t.starts_with("//!") {
                out.push((line, t));
            }
        } else if c[i] == '/' && next == '*' {
            i += 2;
            while i < c.len() && !(c[i] == '*' && c.get(i + 1) == Some(&'/')) {
                line += usize::from(c[i] == '\n');
                i += 1;
            }
            i += 2;
        } else if c[i] == 'r' && (at(1) == '"' || at(1) == '#') && (i == 0 || !ident(c[i - 1])) {
            let mut j = i + 1;
            let mut hashes = 0;
            while j < c.len() && c[j] == '#' {
                hashes += 1;
                j += 1;
            }
            if c.get(j) != Some(&'"') {
                i += 1;
                continue;
            }
            let (start, l0) = (j + 1, line);
            j += 1;
            let closes = |k: usize| c[k] == '"' && (1..=hashes).all(|h| c.get(k + h) == Some(&'#'));
            while j < c.len() && !closes(j) {
                line += usize::from(c[j] == '\n');
                j += 1;
            }
            out.push((l0, c[start..j.min(c.len())].iter().collect()));
            i = j + 1 + hashes;
        } else if c[i] == '"' {
            let (start, l0) = (i + 1, line);
            i += 1;
            while i < c.len() && c[i] != '"' {
                if c[i] == '\\' {
                    i += 1;
                }
                line += usize::from(c.get(i) == Some(&'\n'));
                i += 1;
            }
            out.push((l0, c[start..i.min(c.len())].iter().collect()));
            i += 1;
        } else if c[i] == '\'' {
            if at(1) == '\\' {
                i += 2;
                while i < c.len() && c[i] != '\'' {
                    i += 1;
                }
                i += 1;
            } else if at(2) == '\'' {
                i += 3;
            } else {
                i += 1; // a lifetime
            }
        } else {
            i += 1;
        }
    }
    out
}

fn collect_rs(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            collect_rs(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}
