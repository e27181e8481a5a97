"""fit and explain: the CLI's `--json` to the last digit."""

import json
import threading
import time

import numpy as np
import pytest

import tribo


def cli_json(cli, *args):
    return json.loads(cli(*args, check=False).stdout)


@pytest.mark.parametrize("law", ["coulomb-viscous", "quadratic", "viscous", "poly:3"])
def test_fit_of_a_run_is_the_cli_json(cli, run_dir, law):
    f = tribo.fit(run_dir, law=law)
    assert f.json == cli_json(cli, "fit", "--json", "--law", law, run_dir)
    assert f.law == law and len(f.mu) == len(f.mu_se)


def test_fit_of_a_run_object_and_a_csv_record_are_the_cli_json(cli, store, tmp_path):
    from conftest import runs_of

    run = tribo.open_run(runs_of(store)[1])
    f = tribo.fit(run, law="quadratic", windows=3)
    assert f.json == cli_json(cli, "fit", "--json", "--law", "quadratic", "--windows", "3", run.path)
    assert len(f.windows) == 3
    rec = tmp_path / "bench.csv"
    cli("sim", "--noise", "--disp-noise-m", "3e-7", "--vel-noise-m-s", "2.5e-4", "--held-s", "0.5",
        "--duration-s", "2", "--force-lag-s", "0.003", "-o", rec)
    f = tribo.fit(tribo.read_record(rec))
    j = cli_json(cli, "fit", "--json", rec)
    assert f.json == j
    # The hold before the release (0.5 s at 10 kS/s) is skipped.
    assert f.verdict == "adequate" and 4900 < f.span["start"] < 5100
    assert abs(f.mu[0] - 0.02) < 5 * f.mu_se[0]
    # A flag overriding the record's constant.
    f = tribo.fit(rec, load_n=0.35)
    assert f.json == cli_json(cli, "fit", "--json", "--load-n", "0.35", rec)
    assert f.rig["load_n_from"] == "flag"


def test_fit_of_an_in_memory_record_equals_the_fit_of_its_file(cli, tmp_path):
    rec = tmp_path / "q.csv"
    cli("sim", "--law", "quadratic", "--mu", "0.02,0.01,0.004", "--noise", "-o", rec)
    s = tribo.simulate(law="quadratic", mu=[0.02, 0.01, 0.004], noise=True)
    a = tribo.fit(s, law="quadratic").json
    b = cli_json(cli, "fit", "--json", "--law", "quadratic", rec)
    assert a.pop("record") == "<record>" and b.pop("record") == str(rec)
    assert a == b


def test_explain_is_the_cli_json(cli, store):
    from conftest import runs_of

    d = runs_of(store)[1]  # a quadratic contact
    e = tribo.explain(d, max_steps=2)
    assert e.json == cli_json(cli, "explain", "--json", "--max-steps", "2", d)
    # Its base law is `tribo fit`'s answer, to the last digit.
    assert e.base_fit["mu"] == tribo.fit(d).mu and e.base_fit["mu_se"] == tribo.fit(d).mu_se
    assert e.gap_final <= e.gap_initial


def test_not_analysable_is_its_own_exception_as_the_cli_status_3(cli, tmp_path):
    rec = tmp_path / "still.csv"
    # Friction so high the carriage barely moves: no oscillation to fit.
    cli("sim", "--mu", "0.9,0.0", "--duration-s", "0.5", "-o", rec)
    p = cli("fit", "--json", rec, check=False)
    assert p.returncode == 3 and json.loads(p.stdout)["verdict"] == "not-analysable"
    with pytest.raises(tribo.NotAnalysable) as e:
        tribo.fit(rec)
    assert e.value.reason == json.loads(p.stdout)["reason"]
    assert "not analysable" in str(e.value) and str(rec) in str(e.value)
    with pytest.raises(tribo.NotAnalysable):
        tribo.explain(rec)
    assert issubclass(tribo.NotAnalysable, tribo.TriboError)


def test_a_bad_law_is_a_value_error(run_dir):
    with pytest.raises(ValueError):
        tribo.fit(run_dir, law="cubic-spline")
    with pytest.raises(ValueError):
        tribo.explain(run_dir, only=["no-such-effect"])
    # And a TriboError, as every error of the package (it was a bare ValueError).
    with pytest.raises(tribo.TriboError):
        tribo.fit(run_dir, law="bogus")
    with pytest.raises(tribo.UsageError):
        tribo.explain(run_dir, only=["no-such-effect"])


def test_an_implausible_apparatus_damping_is_refused(run_dir):
    # 1.1 for 1.1e-3: refused, the likely slip named (it fitted μ1 = −1.09, "adequate").
    with pytest.raises(tribo.TriboError) as e:
        tribo.fit(run_dir, apparatus_mu1=1.1)
    assert "1.1e-3" in str(e.value)


def test_a_long_fit_releases_the_gil():
    s = tribo.simulate(law="quadratic", mu=[0.02, 0.01, 0.004], noise=True, duration_s=4)
    done = threading.Event()
    ticks = 0

    def work():
        tribo.explain(s, max_steps=1)
        done.set()

    th = threading.Thread(target=work)
    t0 = time.perf_counter()
    th.start()
    while not done.is_set():
        ticks += 1
        time.sleep(0.001)
    th.join()
    took = time.perf_counter() - t0
    # With the GIL held the whole time this loop could not have run while the fit did.
    assert took > 0.05 and ticks > 0.3 * took / 0.002, (took, ticks)


def test_results_are_typed_objects_with_their_json_kept(run_dir):
    f = tribo.fit(run_dir)
    assert isinstance(f, tribo.Fit)
    assert isinstance(f.law, str) and isinstance(f.verdict, str) and isinstance(f.converged, bool)
    assert isinstance(f.mu, list) and len(f.mu) == 2 and all(type(m) is float for m in f.mu)
    assert len(f.mu_se) == len(f.mu) and all(s is None or type(s) is float for s in f.mu_se)
    assert all(type(p) is float for p in f.p_si) and len(f.p_si_se) == len(f.p_si)
    assert type(f.gap) is float and type(f.noise_floor) is float
    assert isinstance(f.rig, dict) and f.record == str(run_dir) and isinstance(f.defaults, list)
    # The typed fields are the JSON's numbers, not a second computation.
    assert f.mu == f.json["mu"] and f.verdict == f.json["verdict"] and f.gap == f.json["gap"]
    d = f.to_dict()
    assert d == f.json and d is not f.json and json.loads(json.dumps(d)) == d
    e = tribo.explain(run_dir, max_steps=1)
    assert isinstance(e, tribo.Explanation) and isinstance(e.conclusion, str)
    assert isinstance(e.base_fit, tribo.Fit) and e.base_fit.mu == f.mu and e.base_fit.law == f.law
    assert isinstance(e.steps, list) and all(isinstance(s, tribo.Step) for s in e.steps)
    assert all(type(s.gap_after) is float and isinstance(s.effect, str) for s in e.steps)
    assert type(e.gap_initial) is float and type(e.gap_final) is float
    assert e.gap_final == e.json["gap_final"] and e.to_dict() == e.json


def test_typed_errors_reach_python_as_their_exceptions(cli, run_dir, tmp_path):
    # A value out of range: the CLI's status 2, Python's UsageError (a ValueError).
    assert cli("fit", run_dir, "--apparatus-mu1", "1.1", check=False).returncode == 2
    with pytest.raises(tribo.UsageError) as e:
        tribo.fit(run_dir, apparatus_mu1=1.1)
    assert isinstance(e.value, ValueError) and "1.1e-3" in str(e.value)
    # A record with a sample that is not finite: status 3, NotAnalysable naming why.
    rec = tmp_path / "sim.csv"
    cli("sim", "--duration-s", "0.5", "-o", rec)
    lines = rec.read_text().splitlines()
    i = next(k for k, l in enumerate(lines) if l and l[0].isdigit()) + 10
    cols = lines[i].split(",")
    cols[1] = "NaN"
    lines[i] = ",".join(cols)
    nan = tmp_path / "nan.csv"
    nan.write_text("\n".join(lines) + "\n")
    assert cli("fit", nan, check=False).returncode == 3
    with pytest.raises(tribo.NotAnalysable) as e:
        tribo.fit(nan)
    assert e.value.reason == "non-finite" and "not analysable" in str(e.value)


def test_fit_of_a_list_is_each_records_own_fit(store, tmp_path):
    """A list of runs, paths and in-memory records, fitted on every core: each result is the
    record's own fit to the last digit, in the list's order; a record that cannot be fitted
    raises its own error, or with errors="keep" stands in its place."""
    from conftest import runs_of

    runs = runs_of(store)
    sims = [
        tribo.simulate(law="quadratic", mu=[0.02, 0.01, 0.004], noise=True, seed=s)
        for s in (1, 2)
    ]
    items = [runs[2], tribo.open_run(runs[1]), sims[0], str(runs[0]), sims[1]]
    one_by_one = [tribo.fit(r, law="quadratic").json for r in items]
    many = tribo.fit(items, law="quadratic")
    assert [f.json for f in many] == one_by_one
    # Not every record the same: the order is the list's.
    assert len({json.dumps(j["mu"]) for j in one_by_one}) == len(items)
    # A tuple, another law.
    assert [f.json for f in tribo.fit(tuple(items[:2]), law="viscous")] == [
        tribo.fit(r, law="viscous").json for r in items[:2]
    ]
    assert tribo.fit([], law="quadratic") == []
    # A record at rest: nothing to fit.
    rest = tribo.simulate(duration_s=0.5)
    rest.x = np.zeros_like(rest.x)
    rest.v = np.zeros_like(rest.v)
    with pytest.raises(tribo.TriboError) as alone:
        tribo.fit(rest)
    with pytest.raises(tribo.TriboError) as in_list:
        tribo.fit([items[0], rest])
    assert type(in_list.value) is type(alone.value) and str(in_list.value) == str(alone.value)
    kept = tribo.fit([items[0], rest, items[2]], law="quadratic", errors="keep")
    assert kept[0].json == one_by_one[0] and kept[2].json == one_by_one[2]
    assert type(kept[1]) is type(alone.value) and str(kept[1]) == str(alone.value)
    with pytest.raises(tribo.UsageError):
        tribo.fit([items[0]], errors="ignore")
