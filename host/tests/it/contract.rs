//! The exit contract of `tribo` (README, "Exit status"), walked as a table against the real binary:
//! for every command and every class of input — missing, empty, truncated, damaged, an incomplete
//! run, wrong units, out of range, an unreachable rig, a closed standard output or error — one exit
//! status and one kind of message (`error:` for 1 and 2, `incomplete:` for 3), and never a panic.
//! The signals (130, 143, 129) are walked by `exit_contract.rs`.
//!
//! Before this table: a truncated frame log was *adequate* for `fit` (0) but 3 for `report`; a
//! damaged run vanished from `tribo table` (0, without a word); `rig --speed 0`, `--listen
//! 127.0.0.1:80000`, `fit --load-n 0` and a catalog URL with `?foo=bar` exited 1; a CSV in
//! millimetres under `x_m` and `# load_n=300` were fitted (0); `tribo run` exited 0 with no constant
//! to print, and panicked (101) on a closed standard error.
#![cfg(unix)]

use crate::support::{RigProcess, TRIBO};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// `tribo ARGS` run to its end in `dir` (the spawner of [`crate::support::command`]).
fn tribo_in(dir: &Path, args: &[&str]) -> Output {
    crate::support::command(args)
        .current_dir(dir)
        .output()
        .expect("tribo runs")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// The only run folder of `store`.
fn only_run(store: &Path) -> PathBuf {
    let runs: Vec<PathBuf> = std::fs::read_dir(store)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("meta.toml").is_file())
        .collect();
    assert_eq!(runs.len(), 1, "{runs:?}");
    runs[0].clone()
}

fn copy_run(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        if e.path().is_file() {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
}

/// Flips one bit in the middle of the payload of a log record a third of the way into `log`:
/// damage (not a torn end) to a wire frame, whose own CRC then fails too, so that no salvage can
/// rescue it (a bit in a record's length or checksum leaves the frame whole: rescued).
fn damage(log: &Path) {
    let mut b = std::fs::read(log).unwrap();
    let r = records(&b);
    let at = r[r.len() / 3];
    let len = u32::from_le_bytes(b[at..at + 4].try_into().unwrap()) as usize;
    b[at + 8 + len / 2] ^= 0x40;
    std::fs::write(log, b).unwrap();
}

/// Byte offsets of the records of a frame log (after its 24-byte header): `len ‖ crc ‖ payload`.
fn records(log: &[u8]) -> Vec<usize> {
    let mut at = 24;
    let mut out = Vec::new();
    while at + 8 <= log.len() {
        out.push(at);
        let len = u32::from_le_bytes(log[at..at + 4].try_into().unwrap()) as usize;
        at += 8 + len;
    }
    out
}

/// The fixtures every row needs, made once: records, a run taken on a virtual rig, and copies of
/// it cut, damaged.
struct Fixtures {
    dir: tempfile::TempDir,
    rig: RigProcess,
}

impl Fixtures {
    fn new() -> Fixtures {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let o = tribo_in(
            d,
            &[
                "sim",
                "--noise",
                "--duration-s",
                "2",
                "-o",
                "good.csv",
                "-q",
            ],
        );
        assert!(o.status.success(), "{}", text(&o.stderr));
        let good = std::fs::read_to_string(d.join("good.csv")).unwrap();
        std::fs::write(d.join("empty.csv"), "").unwrap();
        std::fs::write(d.join("truncated.csv"), &good[..good.len() / 2]).unwrap();
        // Millimetres under a header in metres; a load in mN written as N.
        let mut mm = String::new();
        let mut mn = String::new();
        for l in good.lines() {
            if l.starts_with('#') || l.starts_with("t_s") {
                mm.push_str(l);
                mn.push_str(&l.replace("# load_n=0.3", "# load_n=300"));
            } else {
                let f: Vec<&str> = l.split(',').collect();
                let x: f64 = f[1].parse().unwrap();
                let v: f64 = f[2].parse().unwrap();
                mm.push_str(&format!(
                    "{},{},{},{}",
                    f[0],
                    x * 1e3,
                    v * 1e3,
                    f[3..].join(",")
                ));
                mn.push_str(l);
            }
            mm.push('\n');
            mn.push('\n');
        }
        std::fs::write(d.join("mm.csv"), mm).unwrap();
        std::fs::write(d.join("load300.csv"), mn).unwrap();
        // A run, whole; a copy with its frame log cut in half; a copy with one flipped byte.
        let rig = RigProcess::start(f64::INFINITY);
        let o = tribo_in(
            d,
            &[
                "run", "--load", "0.3", "--port", &rig.addr, "--store", "whole", "-q",
            ],
        );
        assert!(o.status.success(), "{}", text(&o.stderr));
        let run = only_run(&d.join("whole"));
        copy_run(&run, &d.join("cut"));
        let log = d.join("cut/frames.log");
        let n = std::fs::metadata(&log).unwrap().len();
        std::fs::OpenOptions::new()
            .write(true)
            .open(&log)
            .unwrap()
            .set_len(n / 2)
            .unwrap();
        copy_run(&run, &d.join("damaged"));
        damage(&d.join("damaged/frames.log"));
        std::fs::write(
            d.join("bad-plan.toml"),
            "name = \"p\"\nloads_n = [0.3]\nsettle_tol_c = 0\nsettle_s = -1\n",
        )
        .unwrap();
        Fixtures { dir, rig }
    }

    fn path(&self) -> &Path {
        self.dir.path()
    }
}

/// One row of the contract: a command line, its status, and what its message must say.
struct Row {
    class: &'static str,
    args: Vec<String>,
    status: i32,
    says: &'static str,
}

fn row(class: &'static str, args: &str, status: i32, says: &'static str) -> Row {
    Row {
        class,
        args: args.split_whitespace().map(str::to_string).collect(),
        status,
        says,
    }
}

#[test]
fn every_command_and_input_class_has_one_status_and_one_kind_of_message() {
    let f = Fixtures::new();
    let rig = f.rig.addr.clone();
    let analysis = ["fit", "explain", "onboard"];
    let mut rows = Vec::new();
    for cmd in analysis {
        rows.push(row(
            "missing",
            &format!("{cmd} missing.csv"),
            1,
            "cannot read",
        ));
        rows.push(row(
            "empty",
            &format!("{cmd} empty.csv"),
            1,
            "no header line",
        ));
        rows.push(row(
            "truncated",
            &format!("{cmd} truncated.csv"),
            1,
            "truncated file?",
        ));
        rows.push(row(
            "damaged run",
            &format!("{cmd} damaged"),
            1,
            "tribo pull --salvage",
        ));
        rows.push(row(
            "incomplete run",
            &format!("{cmd} cut"),
            3,
            "tribo pull",
        ));
        rows.push(row(
            "wrong units",
            &format!("{cmd} mm.csv"),
            3,
            "millimetres",
        ));
        rows.push(row("wrong units", &format!("{cmd} load300.csv"), 3, "mN"));
    }
    rows.extend([
        // What each command writes of an incomplete run, it writes; then status 3.
        row(
            "incomplete run",
            "export cut --format csv -o cut.csv",
            3,
            "tribo pull",
        ),
        row(
            "incomplete run",
            "export cut --format parquet -o cut.parquet",
            3,
            "tribo pull",
        ),
        row(
            "incomplete run",
            "report cut --no-png -o rep-cut",
            3,
            "tribo pull",
        ),
        row("incomplete run", "replay cut", 3, "tribo pull"),
        row(
            "partial analysis asked",
            "fit cut --longest-clean-stretch",
            0,
            "analysing what it holds",
        ),
        row(
            "damaged run",
            "export damaged -o d.parquet",
            1,
            "tribo pull --salvage",
        ),
        row(
            "damaged run",
            "report damaged --no-png -o rep-d",
            1,
            "tribo pull --salvage",
        ),
        row("damaged run", "replay damaged", 1, "tribo pull --salvage"),
        row("missing", "export missing.csv -o m.csv", 1, "cannot read"),
        row("missing", "replay missing", 1, "not a run folder"),
        row(
            "missing",
            "campaign missing.toml --dry-run",
            1,
            "cannot read the plan",
        ),
        // Out of range: a usage error, before anything is sent or read.
        row("out of range", "fit good.csv --load-n 0", 2, "--load-n 0"),
        row(
            "out of range",
            "sim --law coulomb --mu 0.1,0.2 -o two.csv",
            2,
            "needs 1 constant(s) in --mu, got 2",
        ),
        row("wrong units", "fit good.csv --load-n 300", 2, "mN"),
        row(
            "wrong units",
            "fit good.csv --mass-kg 40",
            2,
            "40 g is 0.04 kg",
        ),
        row(
            "wrong units",
            "fit good.csv --apparatus-mu1 1.1",
            2,
            "1.1e-3",
        ),
        row(
            "out of range",
            "fit good.csv --apparatus-mu1 -0.001",
            2,
            "--apparatus-mu1",
        ),
        row("out of range", "rig --virtual --speed 0", 2, "--speed"),
        row(
            "out of range",
            "rig --virtual --listen 127.0.0.1:80000",
            2,
            "80000",
        ),
        row("out of range", "rig --listen 127.0.0.1:0", 2, "--virtual"),
        row(
            "out of range",
            "runs --catalog postgres://u@localhost/db?foo=bar",
            2,
            "foo",
        ),
        row(
            "out of range",
            "run --load 0.3 --temp 40 --settle-tol 0 --port tcp://127.0.0.1:1",
            2,
            "settle tolerance",
        ),
        row(
            "out of range",
            "run --load 0.3 --settle-secs -1 --port tcp://127.0.0.1:1",
            2,
            "settle time",
        ),
        row(
            "out of range",
            "run --load -0.1 --port tcp://127.0.0.1:1",
            2,
            "--load",
        ),
        row(
            "out of range",
            "run --load 5 --port tcp://127.0.0.1:1",
            2,
            "--load",
        ),
        row(
            "out of range",
            "campaign bad-plan.toml --dry-run",
            2,
            "settle_tol_c = 0",
        ),
        row("out of range", "panel --listen 127.0.0.1:80000", 2, "80000"),
        row("usage", "fit good.csv --law bogus", 2, "bogus"),
        // No rig there.
        row(
            "unreachable rig",
            "run --load 0.3 --port tcp://127.0.0.1:1 --store s",
            1,
            "nothing listens there",
        ),
        row(
            "unreachable rig",
            "status --port tcp://127.0.0.1:1",
            1,
            "nothing listens there",
        ),
        row(
            "unreachable rig",
            "pull --port tcp://127.0.0.1:1 --store s",
            1,
            "nothing listens there",
        ),
        // Whole: 0.
        row("whole", "fit good.csv", 0, ""),
    ]);
    // Whole runs: each analysis command on the run folder.
    let whole = only_run(&f.path().join("whole"));
    let whole = whole.to_str().unwrap().to_string();
    for args in [
        vec!["fit", &whole],
        vec!["explain", &whole],
        vec!["onboard", &whole],
        vec!["replay", &whole],
        vec!["export", &whole, "--format", "csv", "-o", "w.csv"],
        vec!["report", &whole, "--no-png", "-o", "rep-w"],
    ] {
        rows.push(Row {
            class: "whole",
            args: args.into_iter().map(str::to_string).collect(),
            status: 0,
            says: "",
        });
    }
    // The rig reached: a run on it is whole (0).
    rows.push(row(
        "whole",
        &format!("run --load 0.3 --port {rig} --store more -q"),
        0,
        "",
    ));
    let mut failures = Vec::new();
    for r in &rows {
        let args: Vec<&str> = r.args.iter().map(String::as_str).collect();
        let o = tribo_in(f.path(), &args);
        let (out, err) = (text(&o.stdout), text(&o.stderr));
        let label = match r.status {
            0 => "",
            3 => "incomplete:",
            _ => "error:",
        };
        let ok = o.status.code() == Some(r.status)
            && !err.contains("panicked")
            && err.contains(label)
            && (err.contains(r.says) || out.contains(r.says));
        if !ok {
            failures.push(format!(
                "[{}] tribo {}: status {:?}, want {} with {label:?} and {:?}\n  stderr: {}",
                r.class,
                r.args.join(" "),
                o.status.code(),
                r.status,
                r.says,
                err.trim()
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} rows broke the contract:\n{}",
        failures.len(),
        rows.len(),
        failures.join("\n")
    );
}

/// A campaign with one run damaged: the table, the campaign's report and the campaign's dry run
/// each name it and say how to repair it, and the table and report exit 3 (they were 0, the run
/// silently dropped from its cell; the dry run counted it done).
#[test]
fn a_damaged_run_is_never_silently_left_out_of_a_table_or_report() {
    let f = Fixtures::new();
    let d = f.path();
    std::fs::write(
        d.join("plan.toml"),
        "name = \"c1\"\nloads_n = [0.3]\nrepeats = 2\n",
    )
    .unwrap();
    let o = tribo_in(
        d,
        &[
            "campaign",
            "plan.toml",
            "--port",
            &f.rig.addr,
            "--store",
            "c",
            "--no-prompt",
            "-q",
        ],
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let mut runs: Vec<PathBuf> = std::fs::read_dir(d.join("c"))
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("meta.toml").is_file())
        .collect();
    runs.sort();
    assert_eq!(runs.len(), 2);
    damage(&runs[0].join("frames.log"));
    let name = runs[0].file_name().unwrap().to_str().unwrap().to_string();
    for (args, status) in [
        (vec!["table", "--store", "c"], 3),
        (vec!["table", "--store", "c", "--json"], 3),
        (
            vec!["report", "c1", "--store", "c", "--no-png", "-o", "rep"],
            3,
        ),
        (
            vec!["campaign", "plan.toml", "--store", "c", "--dry-run"],
            0,
        ),
    ] {
        let o = tribo_in(d, &args);
        let (out, err) = (text(&o.stdout), text(&o.stderr));
        assert_eq!(o.status.code(), Some(status), "{args:?}: {out}\n{err}");
        let said = format!("{out}{err}");
        assert!(
            said.contains(&name) && said.contains("tribo pull --salvage"),
            "{args:?} does not name the damaged run {name} and its repair: {said}"
        );
    }
    // The dry run takes it again: one done, one to take.
    let o = tribo_in(d, &["campaign", "plan.toml", "--store", "c", "--dry-run"]);
    assert!(
        text(&o.stdout).contains("1 already done, 1 to take"),
        "{}",
        text(&o.stdout)
    );
}

/// `tribo pull --salvage` that leaves the run whole exits 0, with or without the rig; one that
/// cannot make it whole exits 3 (the rig has moved on to another run: it was 1).
#[test]
fn a_salvage_that_makes_the_run_whole_exits_0_and_one_that_cannot_exits_3() {
    let f = Fixtures::new();
    let d = f.path();
    let whole = only_run(&d.join("whole"));
    // The rig moves on: another run replaces the one in the folder.
    let o = tribo_in(
        d,
        &[
            "run",
            "--load",
            "0.3",
            "--port",
            &f.rig.addr,
            "--store",
            "other",
            "-q",
        ],
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    // A damaged record checksum: the frame inside is whole (its own CRC holds) and is rescued.
    let crc_only = |name: &str| -> PathBuf {
        let p = d.join(name);
        copy_run(&whole, &p);
        let log = p.join("frames.log");
        let mut b = std::fs::read(&log).unwrap();
        let r = records(&b);
        b[r[r.len() / 2] + 4] ^= 0x01;
        std::fs::write(&log, b).unwrap();
        p
    };
    for (name, port) in [
        ("salvage-offline", "tcp://127.0.0.1:1"),
        ("salvage-moved-on", f.rig.addr.as_str()),
    ] {
        let p = crc_only(name);
        let o = tribo_in(
            d,
            &[
                "pull",
                "--salvage",
                p.to_str().unwrap(),
                "--port",
                port,
                "--store",
                "whole",
            ],
        );
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(0), "{name}: {}{err}", text(&o.stdout));
        assert!(!err.contains("panicked"), "{err}");
        let o = tribo_in(d, &["fit", p.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(0), "{name}: {}", text(&o.stderr));
    }
    // A damaged frame: what it held is lost for good, and the rig no longer holds the run.
    let p = d.join("salvage-lost");
    copy_run(&whole, &p);
    damage(&p.join("frames.log"));
    let o = tribo_in(
        d,
        &[
            "pull",
            "--salvage",
            p.to_str().unwrap(),
            "--port",
            &f.rig.addr,
            "--store",
            "whole",
        ],
    );
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{}{err}", text(&o.stdout));
    assert!(
        err.contains("incomplete:") && err.contains("newer run"),
        "{err}"
    );
}

/// `tribo run … 2>&1 | head -2` while heating: no panic (it was exit 101, "failed printing to
/// stderr"), the run recorded and stored whole (it was left to the rig, the store holding a run
/// "recording"), the quiet exit of a closed pipe (0).
#[test]
fn tribo_run_into_a_closed_stderr_stores_the_run_whole() {
    let f = Fixtures::new();
    let d = f.path();
    let cmd = format!(
        "'{TRIBO}' run --port '{}' --store '{}' --load 0.3 --temp 50 --ramp 30 --settle-secs 1 \
         2>&1 | head -2; echo \"status=${{PIPESTATUS[0]}}\"",
        f.rig.addr,
        d.join("piped").display()
    );
    let o = Command::new("bash").args(["-c", &cmd]).output().unwrap();
    let out = text(&o.stdout);
    assert!(out.contains("status=0"), "{out}");
    assert!(!out.contains("panicked"), "{out}");
    let run = only_run(&d.join("piped"));
    let o = tribo_in(d, &["runs", "--store", "piped", "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let r = &v["runs"][0];
    assert_eq!(r["status"], "complete", "{r} ({})", run.display());
    assert!(r["host_mu0"].as_f64().is_some(), "{r}");
}

/// `tribo run` on a rig whose pin cannot move (μ0 = 5: friction above the blades' pull) or whose
/// velocity input is stuck: no constant can be printed, so status 3 as `tribo fit` gives on the
/// same run (it was 0), and the diagnosis names what happened (it said "the displacement channel
/// is saturated … while the pin moves" for a pin that never moved).
#[test]
fn tribo_run_exits_3_when_no_constant_could_be_printed_and_says_why() {
    for (extra, says) in [
        (&["--mu0", "5"][..], "the pin never moves"),
        (
            &["--fault", "stuck:v"][..],
            "the velocity channel reads one value",
        ),
    ] {
        let rig = RigProcess::start_with(f64::INFINITY, extra);
        let dir = tempfile::tempdir().unwrap();
        let o = tribo_in(
            dir.path(),
            &[
                "run", "--load", "0.3", "--port", &rig.addr, "--store", "r", "-q",
            ],
        );
        let (out, err) = (text(&o.stdout), text(&o.stderr));
        assert_eq!(o.status.code(), Some(3), "{extra:?}: {out}{err}");
        assert!(
            err.contains("incomplete:") && err.contains(says),
            "{extra:?}: {err}"
        );
        assert!(!format!("{out}{err}").contains("saturated"), "{out}{err}");
        assert!(!out.contains("NaN"), "{out}");
        // `tribo fit` on the stored run: the same status and the same reason.
        let run = only_run(&dir.path().join("r"));
        let o = tribo_in(dir.path(), &["fit", run.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(3), "{}", text(&o.stderr));
        assert!(text(&o.stderr).contains(says), "{}", text(&o.stderr));
    }
}

/// What the rig did not measure is not invented: the samples without an ECR reading are empty in
/// the CSV export and in the run's own samples.csv, as they are null in JSON (they were filled
/// with the next reading, e.g. 1.0002778e7).
#[test]
fn samples_without_an_ecr_reading_are_empty_in_every_export() {
    let f = Fixtures::new();
    let d = f.path();
    let run = only_run(&d.join("whole"));
    let o = tribo_in(
        d,
        &[
            "export",
            run.to_str().unwrap(),
            "--format",
            "json",
            "-o",
            "w.json",
            "-q",
        ],
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("w.json")).unwrap()).unwrap();
    let ecr = j["columns"]["ecr_ohm"].as_array().unwrap();
    let nulls: Vec<bool> = ecr.iter().map(|v| v.is_null()).collect();
    assert!(
        nulls.iter().any(|n| *n),
        "the run has samples without an ECR reading"
    );
    assert!(nulls.iter().any(|n| !*n));
    let o = tribo_in(
        d,
        &[
            "export",
            run.to_str().unwrap(),
            "--format",
            "csv",
            "-o",
            "w.csv",
            "-q",
        ],
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    for csv in [d.join("w.csv"), run.join("samples.csv")] {
        let text = std::fs::read_to_string(&csv).unwrap();
        let mut lines = text.lines().filter(|l| !l.starts_with('#'));
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let col = header.iter().position(|h| *h == "ecr_ohm").unwrap();
        let empty: Vec<bool> = lines
            .map(|l| l.split(',').nth(col).unwrap().trim().is_empty())
            .collect();
        assert_eq!(empty, nulls, "{}: empty where JSON has null", csv.display());
    }
    // The CSV is read back as it was written, and fits as the run does.
    let o = tribo_in(d, &["fit", "w.csv"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
}

/// One name for a flag across commands, the old ones kept (`run --load`/`--mass`, `fit
/// --load-n`/`--mass-kg`), and `-` for standard input wherever a record is read (`tribo sim -o -`
/// wrote standard output, `tribo fit -` could not read it).
#[test]
fn flags_have_one_name_across_commands_and_a_record_can_come_from_stdin() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = tribo_in(d, &["sim", "-q", "-o", "good.csv"]);
    assert!(o.status.success());
    for args in [
        vec!["fit", "good.csv", "--load", "0.3", "--mass", "0.04"],
        vec!["fit", "good.csv", "--load-n", "0.3", "--mass-kg", "0.04"],
    ] {
        let o = tribo_in(d, &args);
        assert!(o.status.success(), "{args:?}: {}", text(&o.stderr));
    }
    // `run` takes `--load-n` and `--mass-kg` too (refused by range here: parsed, status 2).
    let o = tribo_in(
        d,
        &[
            "run",
            "--load-n",
            "5",
            "--mass-kg",
            "0.04",
            "--port",
            "tcp://127.0.0.1:1",
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("--load"), "{}", text(&o.stderr));
    let cmd = format!("'{TRIBO}' sim -q -o - | '{TRIBO}' fit - --json");
    let o = Command::new("bash")
        .current_dir(d)
        .args(["-c", &cmd])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["verdict"], "adequate", "{v}");
    assert_eq!(v["record"], "-", "{v}");
    for cmd in ["explain", "onboard"] {
        let c = format!("'{TRIBO}' sim -q --noise -o - | '{TRIBO}' {cmd} -");
        let o = Command::new("bash")
            .current_dir(d)
            .args(["-c", &c])
            .output()
            .unwrap();
        assert!(o.status.success(), "{cmd} -: {}", text(&o.stderr));
    }
}

/// A dimensionless record (`tau,y,ydot`) is labelled in its own units: no `s`, `s/m`, `m` or `Hz`
/// on what `fit` and `onboard` print of it (they were).
#[test]
fn a_dimensionless_record_is_labelled_in_its_own_units() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = tribo_in(d, &["sim", "-q", "--noise", "-o", "si.csv"]);
    assert!(o.status.success());
    let (m, k, n) = (0.04f64, 1150.0f64, 0.3f64);
    let (w, l) = ((k / m).sqrt(), n / k);
    let mut csv = String::from("tau,y,ydot\n");
    for line in std::fs::read_to_string(d.join("si.csv")).unwrap().lines() {
        let f: Vec<f64> = match line.split(',').map(|x| x.parse::<f64>()).collect() {
            Ok(f) => f,
            Err(_) => continue,
        };
        csv.push_str(&format!("{},{},{}\n", f[0] * w, f[1] / l, f[2] / (l * w)));
    }
    std::fs::write(d.join("dimless.csv"), csv).unwrap();
    let o = tribo_in(d, &["fit", "dimless.csv"]);
    let out = text(&o.stdout);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let compared = out.lines().find(|l| l.starts_with("compared")).unwrap();
    assert!(
        compared.contains("τ = ") && compared.contains("y′"),
        "{compared}"
    );
    assert!(
        !compared.contains(" s ") && !compared.contains(" s)"),
        "{compared}"
    );
    assert!(!out.contains("s/m"), "{out}");
    let o = tribo_in(d, &["onboard", "dimless.csv"]);
    let out = text(&o.stdout);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let cycles = out.lines().find(|l| l.starts_with("cycles")).unwrap();
    assert!(
        !cycles.contains("Hz") && !cycles.contains(" m ") && cycles.contains("per unit τ"),
        "{cycles}"
    );
}

/// `--json` is one global flag (`cmd::Global`): before or after the subcommand's name, a command
/// with a JSON output prints the same object; a command without one refuses it (2, `error:`, the
/// commands that have one named) before doing anything, never accepting and ignoring it.
#[test]
fn json_is_one_global_flag_taken_anywhere_and_refused_where_there_is_none() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = tribo_in(d, &["sim", "--duration-s", "2", "-o", "good.csv", "-q"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    std::fs::create_dir(d.join("st")).unwrap();
    for lines in [
        [
            vec!["fit", "good.csv", "--json"],
            vec!["--json", "fit", "good.csv"],
            vec!["fit", "--json", "good.csv"],
        ],
        [
            vec!["runs", "--store", "st", "--json"],
            vec!["--json", "runs", "--store", "st"],
            vec!["-q", "runs", "--json", "--store", "st"],
        ],
    ] {
        let outs: Vec<String> = lines
            .iter()
            .map(|args| {
                let o = tribo_in(d, args);
                assert_eq!(
                    o.status.code(),
                    Some(0),
                    "tribo {args:?}: {}",
                    text(&o.stderr)
                );
                let out = text(&o.stdout);
                let v: serde_json::Value = serde_json::from_str(&out)
                    .unwrap_or_else(|e| panic!("tribo {args:?} printed no JSON ({e}): {out}"));
                assert!(v.is_object(), "tribo {args:?}: {out}");
                out
            })
            .collect();
        assert!(
            outs.iter().all(|o| *o == outs[0]),
            "{lines:?} differ: {outs:#?}"
        );
    }
    for args in [
        vec!["devices", "--json"],
        vec!["--json", "devices"],
        vec!["--json", "sim", "--duration-s", "2", "-o", "refused.csv"],
        vec![
            "report",
            "good.csv",
            "--no-png",
            "-o",
            "refused-report",
            "--json",
        ],
    ] {
        let o = tribo_in(d, &args);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "tribo {args:?}: {err}");
        assert!(err.starts_with("error: --json:"), "tribo {args:?}: {err}");
        assert!(
            err.contains(
                "the commands that print one are fit, explain, onboard, runs, selftest, status, sync, table"
            ),
            "tribo {args:?}: {err}"
        );
        assert!(
            o.stdout.is_empty(),
            "tribo {args:?} printed {}",
            text(&o.stdout)
        );
    }
    assert!(
        !d.join("refused.csv").exists(),
        "a refused `sim --json` wrote its record"
    );
    assert!(
        !d.join("refused-report").exists(),
        "a refused `report --json` wrote its report"
    );
}
