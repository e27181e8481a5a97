"""Opening runs (complete and damaged) and records, as numpy arrays."""

import numpy as np
import pytest

import tribo


def test_a_complete_run_opens_as_float64_arrays_in_si(run_dir):
    run = tribo.open_run(run_dir)
    assert run.complete and run.status == "complete" and run.missing_blocks == []
    n = len(run)
    assert n > 5000
    for a in (run.t, run.x, run.v, run.ft, run.temp, run.ecr):
        assert isinstance(a, np.ndarray) and a.dtype == np.float64 and a.shape == (n,)
    assert not run.mask.any() and run.mask.dtype == bool
    # The sample grid: t is sample i's time at the run's rate.
    np.testing.assert_allclose(np.diff(run.t), 1.0 / run.sample_rate_hz, rtol=1e-9)
    # Released 667 µm out of equilibrium, in metres.
    assert 6.5e-4 < run.x[0] < 6.8e-4
    # The same samples as the run's CSV written by the store (samples.csv).
    csv = tribo.read_record(run_dir / "samples.csv")
    np.testing.assert_array_equal(run.t, csv.t)
    np.testing.assert_array_equal(run.x, csv.x)
    np.testing.assert_array_equal(run.v, csv.v)
    np.testing.assert_array_equal(run.ft, csv.ft)
    assert run.rig == csv.rig
    assert run.meta["id"] == run_dir.name
    ob = run.onboard
    assert ob is not None and 0.015 < ob["best"]["mu0"] < 0.025 and ob["best"]["mu0_se"] > 0


def test_a_run_converts_to_pandas_and_polars(run_dir):
    run = tribo.open_run(run_dir)
    df = run.to_pandas()
    assert list(df.columns)[:3] == ["t_s", "x_m", "v_m_s"] and len(df) == len(run)
    np.testing.assert_array_equal(df["x_m"].to_numpy(), run.x)
    pl = run.to_polars()
    np.testing.assert_array_equal(pl["v_m_s"].to_numpy(), run.v)


def test_a_damaged_run_is_refused_unless_allowed_and_its_holes_are_nan(run_dir, damaged_run):
    with pytest.raises(tribo.IncompleteRun) as e:
        tribo.open_run(damaged_run)
    assert "allow_incomplete=True" in str(e.value) and str(damaged_run) in str(e.value)
    run = tribo.open_run(damaged_run, allow_incomplete=True)
    whole = tribo.open_run(run_dir)
    assert not run.complete and run.missing_blocks, run.completeness
    assert "missing" in run.completeness and run.recovery is not None
    held = ~run.mask
    assert run.mask.any() and held.any()
    # Holes: NaN in every channel, exactly where the mask says.
    for a in (run.x, run.v, run.ft):
        np.testing.assert_array_equal(np.isnan(a), run.mask)
    # What is held is the run's own samples, in their place; t is defined everywhere.
    m = min(len(run), len(whole))
    np.testing.assert_array_equal(run.t[:m], whole.t[:m])
    np.testing.assert_array_equal(run.x[:m][held[:m]], whole.x[:m][held[:m]])
    np.testing.assert_array_equal(run.v[:m][held[:m]], whole.v[:m][held[:m]])
    # The fit refuses it too, with the same type.
    with pytest.raises(tribo.IncompleteRun):
        tribo.fit(damaged_run)


def test_an_incomplete_run_names_its_missing_blocks(damaged_run):
    with pytest.raises(tribo.IncompleteRun) as e:
        tribo.open_run(damaged_run)
    run = tribo.open_run(damaged_run, allow_incomplete=True)
    assert e.value.missing_blocks == run.missing_blocks != []
    assert e.value.path == str(damaged_run)
    assert str(run.missing_blocks[0]) in str(e.value)


def test_a_record_reads_and_a_bad_one_names_file_line_and_column(tmp_path):
    good = tmp_path / "r.csv"
    good.write_text("# mass_kg=0.04\n# stiffness_n_per_m=1150\n# load_n=0.3\nt_s,x_m,v_m_s\n" + "".join(f"{i * 1e-4},{1e-4 - i * 1e-7},-0.01\n" for i in range(10)))
    r = tribo.read_record(good)
    assert r.rig == (0.04, 1150.0, 0.3) and r.ft is None
    np.testing.assert_array_equal(r.x, [1e-4 - i * 1e-7 for i in range(10)])
    bad = tmp_path / "bad.csv"
    bad.write_text("# mass_kg=0.04\n# stiffness_n_per_m=1150\n# load_n=0.3\nt_s,x_m,v_m_s\n0,1e-4,0\n0.0001,oops,-0.01\n")
    with pytest.raises(tribo.RecordError) as e:
        tribo.read_record(bad)
    assert e.value.file == str(bad) and e.value.line == 6 and e.value.column is not None
    assert "line 6" in str(e.value) and str(bad) in str(e.value)
    assert isinstance(e.value, tribo.TriboError)
    with pytest.raises(tribo.RecordError) as e:
        tribo.read_record(tmp_path / "absent.csv")
    assert e.value.file == str(tmp_path / "absent.csv")


def test_a_run_folder_that_is_not_one_is_a_tribo_error(tmp_path):
    with pytest.raises(tribo.TriboError) as e:
        tribo.open_run(tmp_path)
    assert "meta.toml" in str(e.value)


def test_simulate_is_tribo_sim(tmp_path, cli):
    out = tmp_path / "s.csv"
    cli("sim", "--law", "quadratic", "--mu", "0.02,0.01,0.005", "--noise", "--duration-s", "1.5", "-o", out)
    s = tribo.simulate(law="quadratic", mu=[0.02, 0.01, 0.005], noise=True, duration_s=1.5)
    f = tribo.read_record(out)
    for a, b in [(s.t, f.t), (s.x, f.x), (s.v, f.v), (s.ft, f.ft)]:
        np.testing.assert_array_equal(a, b)
    assert s.rig == f.rig and s.path is None
    with pytest.raises(ValueError) as e:
        tribo.simulate(law="no-such-law")
    assert "no-such-law" in str(e.value)
