"""``particles wedge`` on a two-worker LocalCluster: every variant in its own folder, the index,
the contact sheet, a diverging variant recorded while the others go on, the same bytes as
``particles run`` with the same settings, --resume (on a cluster given by --scheduler), a worker
killed mid-variant (slow). Bad values are refused before anything renders."""
import csv
import os
import signal
import sys
import threading
import time

import pytest
from PIL import Image

from runhelp import assert_whole_frames, call, particles, same_bytes

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

CONFIG = """seed = 2
fps = 30
frames = {frames}
[solver]
integrator = "symplectic_euler"
h = {h}
[render]
width = 48
height = 32
[[emitters]]
effect = "sparks"
rate = {rate}
drag = {drag}
[[colliders]]
type = "plane"
"""


def write_cfg(folder, name="fx", frames=6, h=0.0333334, rate=400.0, drag=0.4):
    path = folder / f"{name}.toml"
    path.write_text(CONFIG.format(frames=frames, h=h, rate=rate, drag=drag))
    return path


def test_variant_configs_are_written_as_toml_that_reads_back_equal():
    from particles_tools.wedge.tomlout import dumps

    data = {"name": 'say "hi"\n\u00e9\U0001f525', "seed": 7, "h": 0.004166667, "on": False,
            "odd key": {"a.b": [1, 2.5, -3e-9], "empty": []},
            "emitters": [{"effect": "sparks", "rate": 1800, "size": [[0.0, 0.05], [1.0, 0.01]]},
                         {"bursts": [{"time": 0.0, "count": 10}]}]}
    assert tomllib.loads(dumps(data)) == data
    with pytest.raises(ValueError):
        dumps({"x": float("nan")})


def read_index(out):
    with open(out / "index.csv", newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def cluster():
    """Two worker processes, one task thread each, as ``particles wedge`` starts by default."""
    from particles_tools.wedge.farm import local_cluster

    c = local_cluster(2)
    yield c
    c.close()


@pytest.mark.slow
def test_wedge_renders_variants_index_sheet_and_records_a_diverging_one(tmp_path):
    # explicit drag k = 1e6 1/s at h = 1/30 s multiplies speeds by ~3e4 a step: non-finite by frame 9
    cfg = write_cfg(tmp_path, frames=12)
    out = tmp_path / "w"
    r = particles("wedge", cfg, "--set", "emitters.0.rate=200,400",
                  "--set", "emitters.0.drag=0.5,1e6", "--workers", "2", "--out", out)
    assert r.returncode == 3, r.stderr
    errors = [line for line in r.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 2 and all("diverged" in e and "emitters.0.drag=1e6" in e for e in errors), r.stderr
    assert "Traceback" not in r.stderr
    assert "variants 4/4, 2 failed" in r.stderr and "frames" in r.stderr  # the progress bar
    rows = read_index(out)
    assert [row["variant"] for row in rows] == ["v000", "v001", "v002", "v003"]
    assert [(row["emitters.0.rate"], row["emitters.0.drag"]) for row in rows] == [
        ("200", "0.5"), ("200", "1e6"), ("400", "0.5"), ("400", "1e6")]
    for row in rows:
        n = assert_whole_frames(out / row["variant"])
        assert int(row["frames"]) == n
        if row["emitters.0.drag"] == "1e6":
            assert row["status"] == "failed" and row["exit_code"] == "3"
            assert "diverged" in row["message"] and "h=0.03333" in row["message"]
            assert 1 <= n < 12  # the frames before the divergence are kept, whole
        else:
            assert row["status"] == "ok" and row["exit_code"] == "0" and n == 12
            assert int(row["peak_particles"]) > 0 and row["dropped"] == "0"
            assert float(row["wall_s"]) > 0
    # twice the rate, about twice the particles
    peaks = [int(row["peak_particles"]) for row in rows if row["status"] == "ok"]
    assert 1.6 < peaks[1] / peaks[0] < 2.4
    assert len({row["worker"] for row in rows}) == 2  # both workers took variants
    with Image.open(out / "contact_sheet.png") as sheet:
        sheet.load()
        # 2 x 2 grid (one column per drag value) of 48 x 32 frames in cells at least 120 wide
        assert sheet.width > 2 * 120 and sheet.height > 2 * 32
        assert sheet.width < 3 * 120 + 40
    # a variant renders the same bytes as `particles run` with the same settings, written by hand
    # or as the wedge wrote them (v002.toml)
    ref = write_cfg(tmp_path, name="fx_400", frames=12, rate=400, drag=0.5)
    for config, folder in ((ref, "ref"), (out / "v002.toml", "ref2")):
        code, _, err = call("run", config, "--out", tmp_path / folder, "--quiet")
        assert code == 0, err
        assert same_bytes(out / "v002", tmp_path / folder) == 12


@pytest.mark.slow
def test_resume_skips_finished_variants_and_finishes_a_partial_one(tmp_path, cluster):
    cfg = write_cfg(tmp_path)
    out = tmp_path / "w"
    args = ["wedge", cfg, "--seeds", "2", "--scheduler", cluster.scheduler_address, "--out", out,
            "--quiet"]
    assert call(*args)[0] == 0
    assert [r["seed"] for r in read_index(out)] == ["2", "3"]
    whole = {f: (out / "v001" / f).read_bytes() for f in os.listdir(out / "v001")
             if f.startswith("frame_")}
    # as if the wedge had been stopped while v001 was at frame 3
    rows = read_index(out)
    rows[1].update(status="pending", exit_code="", frames="")
    with open(out / "index.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    for k in range(3, 6):
        os.remove(out / "v001" / f"frame_{k:05d}.png")
    (out / "v001" / ".frame_00003.png.tmp").write_bytes(b"\x89PNG half")
    v000 = {f: os.stat(out / "v000" / f).st_mtime_ns for f in os.listdir(out / "v000")}

    code, _, err = call(*args)  # without --resume the folder is refused, untouched
    assert code == 2 and "--resume" in err and len(err.strip().splitlines()) == 1, err
    code, stdout, err = call(*args, "--resume")
    assert code == 0, err
    assert "1 already done" in stdout
    rows = read_index(out)
    assert [r["status"] for r in rows] == ["ok", "ok"]
    assert rows[1]["resumed_at"] == "3"
    assert {f: os.stat(out / "v000" / f).st_mtime_ns for f in os.listdir(out / "v000")} == v000
    assert assert_whole_frames(out / "v001") == 6
    assert {f: (out / "v001" / f).read_bytes() for f in whole} == whole

    code, _, err = call("wedge", cfg, "--seeds", "3", "--scheduler", cluster.scheduler_address,
                        "--out", out, "--quiet", "--resume")
    assert code == 2 and "other settings (seeds)" in err, err


@pytest.mark.slow
def test_a_killed_worker_s_variant_is_rerun_elsewhere_with_no_torn_frames(tmp_path, cluster):
    from distributed import Client

    cfg = write_cfg(tmp_path, frames=24, h=0.0005)  # 67 substeps a frame: slow enough to catch
    out = tmp_path / "w"
    got = {}
    wedge = threading.Thread(target=lambda: got.update(r=call(
        "wedge", cfg, "--set", "emitters.0.rate=300,600", "--scheduler", cluster.scheduler_address,
        "--out", out, "--quiet")), daemon=True)
    wedge.start()
    victim = None
    with Client(cluster.scheduler_address) as client:
        deadline = time.monotonic() + 120
        while victim is None and time.monotonic() < deadline and wedge.is_alive():
            running = [vid for vid in ("v000", "v001") if (out / vid / "frame_00002.png").exists()
                       and not (out / vid / "frame_00023.png").exists()]
            if running:
                vid = running[0]
                addr = next((a for a, keys in client.processing().items()
                             if any(f"wedge-{vid}-" in str(k) for k in keys)), None)
                if addr is not None:
                    pid = client.run(os.getpid, workers=[addr])[addr]
                    os.kill(pid, signal.SIGKILL)
                    victim = (vid, pid)
            time.sleep(0.005)
        wedge.join(timeout=150)
        state = (client.processing(), {v: sorted(os.listdir(out / v)) for v in ("v000", "v001")
                                       if (out / v).is_dir()})
    assert victim is not None, "no variant was caught mid-way"
    assert "r" in got, f"the wedge did not finish after killing {victim}: {state}"
    code, stdout, err = got["r"]
    assert code == 0, err
    rows = {r["variant"]: r for r in read_index(out)}
    vid, pid = victim
    row = rows[vid]
    assert row["status"] == "ok" and not row["worker"].endswith(f":{pid}")
    assert int(row["resumed_at"]) >= 3  # the rerun kept the whole frames the dead worker left
    assert assert_whole_frames(out / vid) == 24
    assert not [f for f in os.listdir(out / vid) if f.endswith(".tmp")]
    ref_cfg = write_cfg(tmp_path, name="ref", frames=24, h=0.0005,
                        rate=300 if vid == "v000" else 600)
    code, _, err = call("run", ref_cfg, "--out", tmp_path / "ref", "--quiet")
    assert code == 0, err
    assert same_bytes(out / vid, tmp_path / "ref") == 24


BAD = [  # flags, the one error line (or the start of it)
    (["--set", "emitters.0.rate=100,-5"],
     "--set emitters.0.rate=-5: emitters[0].rate: -5 is not allowed"),
    (["--set", "emitters.0.rate=100,200", "--set", "solver.hh=0.01"],
     "--set solver.hh=0.01: solver.hh: unknown key; did you mean 'h'? (variants v000, v001)"),
    (["--set", "emitters.2.rate=1"],
     "--set emitters.2.rate: emitters has 1 item(s); index 2 is out of range"),
    (["--set", "rate"], "--set: 'rate' is not KEY=V1,V2,..."),
    (["--set", "solver.integrator=rk4,bogus"],
     "--set solver.integrator=bogus: solver.integrator: 'bogus' is not allowed"),
    (["--seeds", "3", "--set", "seed=1,2"], "--seeds and --set seed=...: choose one"),
    (["--seeds", "2", "--frames", "0"], "--frames: 0 is not allowed"),
    (["--seeds", "2", "--workers", "0"], "--workers: 0 is not allowed"),
    (["--seeds", "2", "--workers", "100000"], "--workers: 100000 is not allowed: must be 1 to"),
    (["--seeds", "2", "--sheet-frame", "6"],
     "--sheet-frame: 6 is not a frame of variant v000 (frames 0..5)"),
    (["--set", "a=" + ",".join("0" * 101), "--set", "b=" + ",".join("0" * 101)], "10,201 variants"),
]


@pytest.mark.parametrize("flags, expected", BAD)
def test_bad_input_is_one_line_naming_key_and_variant_and_nothing_is_written(tmp_path, flags,
                                                                             expected):
    cfg = write_cfg(tmp_path)
    code, out, err = call("wedge", cfg, *flags, "--out", tmp_path / "w")
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and expected in lines[0], err
    assert lines[0].startswith("error: ") and "Traceback" not in err
    assert not (tmp_path / "w").exists()
