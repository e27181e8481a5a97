//! The `tribo sim` / `tribo fit --json` command-line contract that other tools rely on.

use std::process::Command;

fn tribo(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tribo"))
        .args(args)
        .output()
        .expect("run tribo")
}

fn number_array(json: &str, key: &str) -> Vec<f64> {
    let start = json
        .find(&format!("\"{key}\": ["))
        .unwrap_or_else(|| panic!("no {key} in {json}"));
    let rest = &json[start + key.len() + 5..];
    let end = rest.find(']').unwrap();
    rest[..end]
        .split(',')
        .map(|s| s.trim().parse().unwrap())
        .collect()
}

fn number(json: &str, key: &str) -> f64 {
    let start = json
        .find(&format!("\"{key}\": "))
        .unwrap_or_else(|| panic!("no {key} in {json}"));
    let rest = &json[start + key.len() + 4..];
    let end = rest.find([',', '}']).unwrap();
    rest[..end].trim().parse().unwrap()
}

#[test]
fn sim_then_fit_json_recovers_the_constants() {
    let dir = std::env::temp_dir().join(format!("tribo-cli-fit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let rec = dir.join("rec.csv");
    let rec_s = rec.to_str().unwrap();
    let out = tribo(&[
        "sim",
        "--law",
        "coulomb-viscous",
        "--mu",
        "0.03,0.012",
        "--load-n",
        "0.3",
        "--duration-s",
        "1.5",
        "--noise",
        "-o",
        rec_s,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&rec).unwrap();
    assert!(text.contains("# mass_kg=0.04") && text.contains("t_s,x_m,v_m_s"));

    let out = tribo(&["fit", rec_s, "--law", "coulomb-viscous", "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json = String::from_utf8(out.stdout).unwrap();
    let json = json.trim();
    assert!(json.starts_with('{') && json.ends_with('}') && json.lines().count() == 1);
    assert!(json.contains("\"law\": \"coulomb-viscous\""), "{json}");
    let mu = number_array(json, "mu");
    assert_eq!(mu.len(), 2);
    assert!(
        (mu[0] - 0.03).abs() < 1e-3 && (mu[1] - 0.012).abs() < 2e-4,
        "{mu:?}"
    );
    let gap = number(json, "gap");
    assert!((0.0..1e-2).contains(&gap), "gap {gap}");

    // The quadratic law on the same record: three constants, μ2 ≈ 0.
    let out = tribo(&["fit", rec_s, "--law", "quadratic", "--json"]);
    let json = String::from_utf8(out.stdout).unwrap();
    let mu = number_array(&json, "mu");
    assert_eq!(mu.len(), 3, "{json}");
    assert!(mu[2].abs() < 1e-3, "{mu:?}");

    // Bad input: a clear error, not a panic.
    std::fs::write(dir.join("bad.csv"), "t_s,x_m,v_m_s\n0,1e-4,0\n1e-4,NaN,0\n").unwrap();
    let out = tribo(&[
        "fit",
        dir.join("bad.csv").to_str().unwrap(),
        "--law",
        "coulomb",
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("line 3") && !err.contains("panicked"), "{err}");
    let out = tribo(&["fit", rec_s, "--law", "cubic-banana"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown law"));
    let _ = std::fs::remove_dir_all(&dir);
}
