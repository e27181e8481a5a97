"""Catalog queries and Parquet round trips (pyarrow and DuckDB, every value)."""

import json
import math

import duckdb
import numpy as np
import pyarrow.parquet as pq
import pytest

import tribo
from conftest import runs_of


def test_catalog_runs_are_tribo_runs_json(cli, store):
    t = tribo.catalog(store).runs()
    j = json.loads(cli("runs", "--json", "--store", store).stdout)
    assert len(t) == len(j["runs"]) == 3
    for row, c in zip(t, j["runs"]):
        for k, v in c.items():
            assert row[k] == (str(v) if k == "path" else v), k
    assert t.damaged == j["damaged"] == []


def test_catalog_filters(cli, store):
    cat = tribo.catalog(store)
    assert sorted(cat.runs(load=0.3)["load_n"]) == [0.3, 0.3]
    assert cat.runs(load=(0.4, 0.6))["load_n"] == [0.5]
    assert len(cat.runs(load="0.1..0.4")) == 2
    assert len(cat.runs(status="complete")) == 3
    assert len(cat.runs(status="incomplete")) == 0
    assert len(cat.runs(temp=22)) == len(json.loads(cli("runs", "--json", "--temp", "22", "--store", store).stdout)["runs"])
    df = cat.runs().to_pandas()
    assert list(df["load_n"].sort_values()) == [0.3, 0.3, 0.5]
    assert cat.runs().to_polars().height == 3
    with pytest.raises(ValueError):
        cat.runs(status="finished")
    with pytest.raises(tribo.TriboError) as e:
        tribo.catalog(store / "nowhere").runs()
    assert "no run store" in str(e.value)


def test_catalog_by_rig_and_day_as_the_cli(cli, store):
    import datetime

    cat = tribo.catalog(store)
    rows = cat.runs().rows
    day = datetime.date.fromisoformat(rows[0]["created"][:10])
    ours = [r for r in rows if r["created"][:10] == day.isoformat()]
    assert len(cat.runs(since=day, until=day)) == len(ours) > 0
    assert len(cat.runs(since=day.isoformat())) == len([r for r in rows if r["created"][:10] >= day.isoformat()])
    assert len(cat.runs(until=day - datetime.timedelta(days=1))) == len(
        [r for r in rows if r["created"][:10] < day.isoformat()]
    )
    for args in (["--since", day.isoformat()], ["--until", day.isoformat()]):
        kw = {args[0][2:]: args[1]}
        j = json.loads(cli("runs", "--json", "--store", store, *args).stdout)
        assert [r["id"] for r in cat.runs(**kw)] == [r["id"] for r in j["runs"]]
    serial = rows[0]["serial"]
    mine = cat.runs(rig=serial)
    assert len(mine) == len([r for r in rows if r["serial"] == serial]) > 0
    j = json.loads(cli("runs", "--json", "--store", store, "--rig", serial).stdout)
    assert [r["id"] for r in mine] == [r["id"] for r in j["runs"]]
    with pytest.raises(ValueError):
        cat.runs(since="2026-13-01")
    with pytest.raises(ValueError):
        cat.runs(since="2026-02-01", until="2026-01-31")
    with pytest.raises(TypeError):
        cat.runs(since=datetime.datetime(2026, 1, 1))


def test_a_damaged_run_is_listed_as_damaged(tmp_path, store, damaged_run, cli):
    import shutil

    s = tmp_path / "store"
    shutil.copytree(store, s)
    shutil.copytree(damaged_run, s / (damaged_run.name + "-copy"))
    t = tribo.catalog(s).runs()
    assert len(t) == 3 and len(t.damaged) == 1
    assert t.damaged == json.loads(cli("runs", "--json", "--store", s).stdout)["damaged"]


def same(a, b):
    return a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))


def test_a_run_in_parquet_holds_every_sample_and_its_metadata(tmp_path, cli, run_dir):
    out = tmp_path / "run.parquet"
    cli("export", run_dir, "--format", "parquet", "-o", out)
    run = tribo.open_run(run_dir)
    t = pq.read_table(out)
    cols = {"t_s": run.t, "x_m": run.x, "v_m_s": run.v, "ft_n": run.ft, "temp_c": run.temp, "ecr_ohm": run.ecr}
    assert t.num_rows == len(run)
    for name, a in cols.items():
        assert str(t.schema.field(name).type) == "double"
        np.testing.assert_array_equal(t.column(name).to_numpy(), a)
    np.testing.assert_array_equal(t.column("sample_index").to_numpy(), np.arange(len(run)))
    np.testing.assert_array_equal(t.column("ecr_range").to_numpy(), run.ecr_range)
    md = {k.decode(): v.decode() for k, v in t.schema.metadata.items()}
    assert json.loads(md["tribo.meta"]) == run.meta
    assert json.loads(md["tribo.result"]) == run.results
    assert json.loads(md["tribo.units"])["x_m"] == "m" and json.loads(md["tribo.units"])["ecr_ohm"] == "Ω"
    assert json.loads(md["tribo.gaps"]) == [list(g) for g in run.gaps]
    # DuckDB reads the same values.
    con = duckdb.connect()
    rows = con.execute(f"select t_s, x_m, v_m_s, ft_n, temp_c, ecr_ohm, sample_index from '{out}' order by sample_index").fetchnumpy()
    for name, a in cols.items():
        np.testing.assert_array_equal(rows[name], a)
    # The package writes the same file.
    out2 = tmp_path / "run2.parquet"
    assert run.to_parquet(out2) == len(run)
    assert out2.read_bytes() == out.read_bytes()


def test_a_record_in_parquet(tmp_path, cli):
    rec = tmp_path / "r.csv"
    cli("sim", "--noise", "--temp-c", "40", "--duration-s", "1", "-o", rec)
    out = tmp_path / "r.parquet"
    cli("export", rec, "--format", "parquet", "-o", out)
    r = tribo.read_record(rec)
    t = pq.read_table(out)
    for name, a in [("t_s", r.t), ("x_m", r.x), ("v_m_s", r.v), ("ft_n", r.ft), ("temp_c", r.temp)]:
        np.testing.assert_array_equal(t.column(name).to_numpy(), a)
    rig = json.loads(t.schema.metadata[b"tribo.rig"])
    assert (rig["mass_kg"], rig["stiffness_n_per_m"], rig["load_n"]) == r.rig
    got = duckdb.sql(f"select x_m from '{out}'").fetchnumpy()["x_m"]
    np.testing.assert_array_equal(got, r.x)


def test_the_catalog_in_parquet(tmp_path, cli, store):
    out = tmp_path / "cat.parquet"
    cli("export", "--catalog", "--store", store, "--format", "parquet", "-o", out)
    rows = tribo.catalog(store).runs().rows
    t = pq.read_table(out).to_pylist()
    assert len(t) == len(rows) == 3
    for a, b in zip(t, rows):
        assert set(a) == set(b)
        for k in a:
            assert same(a[k], b[k]), (k, a[k], b[k])
    d = duckdb.sql(f"select id, load_n, host_mu0, host_mu0_se, status from '{out}' order by id").fetchall()
    exp = sorted((r["id"], r["load_n"], r["host_mu0"], r["host_mu0_se"], r["status"]) for r in rows)
    assert d == exp
    out2 = tmp_path / "cat2.parquet"
    assert tribo.catalog(store).to_parquet(out2) == 3
    assert out2.read_bytes() == out.read_bytes()


def test_export_errors(tmp_path, cli):
    p = cli("export", tmp_path / "absent.csv", "-o", tmp_path / "x.parquet", check=False)
    assert p.returncode == 1 and "absent.csv" in p.stderr
    with pytest.raises(tribo.RecordError):
        tribo.export_parquet(tmp_path / "absent.csv", tmp_path / "x.parquet")
