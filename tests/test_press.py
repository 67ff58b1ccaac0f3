# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage press (issue 11) on a tiny sheet: 8 fibers laid down for 6 ms on a 1 x 1 mm fabric piece
(real stiffness and inertia, fiber-fiber contact inside the Newton solves), then pressed.

- velocity mode: the plate, moved by fix wall/fiber/dlvo from its own displacement output, stops
  exactly at ``target_thickness_m`` above the fabric top (the highest yarn point, computed here
  from fabric.h5) and rests there for the hold;
- pressure mode: the servo's target follows the ramp / hold / unload / release schedule computed
  here from the scene, the plate never passes the fabric top, and the yarn reaction is reported;
- the overlap guard stops a crafted over-pressing (plate driven fast to 1 um above the fabric top)
  with exit status 1 and a message, leaving no press products;
- bad press sections (negative speed, a target thickness above the sheet, no lay-down products)
  exit 2 naming the field, and write nothing;
- 1 and 2 MPI ranks give the same pressed sheet.

The physics of the plate under load (log-cabin stack vs the continuous-beam closed form, the
servo holding a pressure, spring-back, force balance) is tested on a stack of straight fibers in
tests/test_press_stack.py: a sparse 1 mm^2 sheet lies partly in the fabric's valleys and carries
almost no load before the plate reaches the fabric top.
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

pytestmark = pytest.mark.system

NAME = "tiny_press"
BASE = f"""
name: {NAME}
seed: 3
run: {{timestep_s: 1.0e-7, duration_s: 1.0e-3}}
domain: {{lo_m: [0.0, 0.0, 0.0], hi_m: [1.0e-3, 1.0e-3, 3.437e-3]}}
fibers: {{count: 8, length_m: 0.6e-3, width_m: 20.0e-6, segments: 12,
         youngs_modulus_Pa: 10.0e+9, shear_modulus_Pa: 4.0e+9}}
fiber_generation: {{placement_lo_m: [0.0, 0.0, 2.66e-3], placement_hi_m: [1.0e-3, 1.0e-3, 2.76e-3]}}
fabric: {{size_x_m: 1.0e-3, size_y_m: 1.0e-3}}
flow: {{delta_p_Pa: 100.0, cell_size_m: 50.0e-6, height_above_fabric_m: 0.8e-3}}
laydown: {{terms: [steric], max_time_s: 0.006, check_interval_s: 5.0e-4, settle_speed_m_s: 2.0e-3, settle_checks: 3,
          timestep_s: 1.0e-6, friction_coefficient: 0.5}}
contact: {{model: fiber_dlvo, terms: [steric]}}
"""


def _cli(cmd: list[str], args: list[str], cwd: Path, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*cmd, *args], cwd=cwd, capture_output=True, text=True, errors="replace",
                          timeout=timeout)


@pytest.fixture(scope="module")
def sheet(tmp_path_factory: pytest.TempPathFactory, build_dir: Path,
          fiberform_cmd: list[str]) -> Path:
    """A folder with the lay-down products of the tiny scene (runs/tiny_press/...)."""
    if not (build_dir / "bin" / "fiberdem").is_file():
        pytest.skip("fiberdem not built")
    work = tmp_path_factory.mktemp("press")
    (work / "base.yaml").write_text(BASE)
    for stage in ("generate", "fabric", "flow", "laydown"):
        proc = _cli(fiberform_cmd, [stage, "base.yaml", "--build-dir", str(build_dir)], work)
        assert proc.returncode == 0, stage + proc.stdout[-2000:] + proc.stderr[-3000:]
    return work


def _press(work: Path, cmd: list[str], build_dir: Path, press: str, name: str,
           timeout: float = 600) -> subprocess.CompletedProcess[str]:
    (work / f"{name}.yaml").write_text(BASE + f"press: {press}\n")
    return _cli(cmd, ["press", f"{name}.yaml", "--build-dir", str(build_dir)], work, timeout)


def _fabric_top(work: Path) -> float:
    with h5py.File(work / "runs" / NAME / "fabric" / "fabric.h5", "r") as h:
        pts, offs, rad = h["yarns/points"][...], h["yarns/offsets"][...], h["yarns/radius"][...]
    return float(max((pts[offs[k]:offs[k + 1], 2] + rad[k]).max() for k in range(len(rad))))


def _sheet_top(work: Path) -> float:
    """Highest fiber surface of the lay-down's sheet: node z + the node's larger outer half-axis."""
    root = work / "runs" / NAME
    with h5py.File(root / "laydown" / "laydown.h5", "r") as h:
        x, ids = h["sheet/x"][...], h["sheet/fiber_id"][...]
    with h5py.File(root / "fibers" / "fibers.h5", "r") as h:
        off, radii = h["fibers/offsets"][...], h["fibers/radii"][...]
    r = np.concatenate([radii[off[k]:off[k + 1], :2].max(axis=1) for k in ids])
    return float(np.max(x[:, 2] + r))


def test_velocity_mode_stops_at_target_thickness(sheet: Path, fiberform_cmd: list[str],
                                                  build_dir: Path) -> None:
    top, fab = _sheet_top(sheet), _fabric_top(sheet)
    target = 0.5 * (top - fab)  # half-way between the fabric top and the sheet's highest fiber
    assert target > 2e-6, (top, fab)
    proc = _press(sheet, fiberform_cmd, build_dir,
                  f"{{mode: velocity, plate_speed_m_s: 0.01, target_thickness_m: {target!r}, "
                  "hold_time_s: 5.0e-4, output_interval_s: 1.0e-4}", "velocity")
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    out = sheet / "runs" / NAME / "press"
    with h5py.File(out / "press.h5", "r") as h:
        c = h["curve"]
        z, phase, t = c["plate_z"][...], c["phase"][...].astype(str), c["time"][...]
        assert c["plate_z"].attrs["units"] == "m"
        assert h["run"].attrs["fabric_top_z_m"] == pytest.approx(fab, abs=1e-12)
        # the plate starts plate_start_gap_m (default 5 um) above the sheet's highest fiber
        assert z[0] == pytest.approx(top + 5e-6, abs=1e-12)
        hold = phase == "hold"
        assert hold.sum() >= 5, phase
        # plate positions from the fix's own displacement output: stopped at the target
        assert np.all(np.abs(z[hold] - (fab + target)) < 1e-10), z[hold] - (fab + target)
        moving = phase == "moving"
        assert abs(z[moving][-1] - (fab + target)) < 1e-10, z[moving][-1] - (fab + target)
        speed = np.diff(z[moving]) / np.diff(t[moving])
        assert np.all(speed < 0) and np.all(-speed <= 0.01 * (1 + 1e-9)), speed
        assert np.all(np.isfinite(c["thickness_span"][...]))
        assert h["profiles/solid_fraction"].shape[0] == len(z)
        # provenance on the root: scene, seed, code version, upstream hashes
        for key in ("scene_json", "seed", "git_revision", "input_hashes"):
            assert key in h.attrs, key
        assert "laydown_restart" in h.attrs["input_hashes"]
    for name in ("press.png", "curve.png", "sheet.vtu", "report.md", "sheet.restart"):
        assert (out / name).stat().st_size > 0, name
    report = (out / "report.md").read_text()
    assert "plate stopped at" in report and "h_cap in the press's contacts: the law's 2 nm" in report


def test_pressure_mode_follows_its_schedule(sheet: Path, fiberform_cmd: list[str],
                                            build_dir: Path) -> None:
    p, rate, hold, release = 2.0, 4.0e3, 4.0e-4, 3.0e-4
    proc = _press(sheet, fiberform_cmd, build_dir,
                  f"{{mode: pressure, target_pressure_Pa: {p}, pressure_rate_Pa_s: {rate}, "
                  f"hold_time_s: {hold}, release_time_s: {release}, plate_speed_m_s: 0.02, "
                  "output_interval_s: 1.0e-4}", "pressure")
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    fab = _fabric_top(sheet)
    top = _sheet_top(sheet)
    with h5py.File(sheet / "runs" / NAME / "press" / "press.h5", "r") as h:
        c, a = h["curve"], h["run"].attrs
        tc, target = c["time_since_contact"][...], c["target_pressure"][...]
        z, yarn_f = c["plate_z"][...], c["yarn_force"][...]
        pressure, phase, t = c["pressure"][...], c["phase"][...].astype(str), c["time"][...]
        assert c["yarn_force"].attrs["units"] == "N"
        reached, z_servo = int(a["contact_pressure_reached"]), float(a["servo_start_z_m"])
        assert a["contact_pressure_Pa"] == pytest.approx(0.01 * p, rel=1e-12)
    # the plate never passes the fabric top (keyword stop of fix wall/fiber/dlvo)
    assert np.all(z >= fab - 1e-12), (z.min(), fab)
    # the approach: from 5 um above the sheet's highest fiber down at the speed limit, until the
    # plate pressure reaches 1 % of the target (checked at each output: the last approach point
    # is the first at or above it) or the plate reaches the fabric top; only then the schedule
    app = np.nonzero(phase == "approach")[0]
    assert len(app) >= 2 and app[0] == 0 and np.all(np.diff(app) == 1), phase
    assert z[0] == pytest.approx(top + 5e-6, abs=1e-12)
    moving = z[app] > fab + 1e-12
    v = -np.diff(z[app]) / np.diff(t[app])
    assert np.allclose(v[moving[1:]], 0.02, rtol=1e-6), v
    assert np.all(pressure[app[:-1]] < 0.01 * p), pressure[app]
    if reached:
        assert pressure[app[-1]] >= 0.01 * p, pressure[app]
    else:
        assert z[app[-1]] == pytest.approx(fab, abs=1e-12), (z[app[-1]], fab)
    # the servo takes the plate where the approach left it
    assert z_servo == pytest.approx(z[app[-1]], abs=1e-15), (z_servo, z[app[-1]])
    assert np.all(tc[app] == -1.0)
    # the servo's target: ramp at `rate` to p, hold, unload at `rate`, zero in the release; the
    # clock starts at the servo's first contact (time since contact < 0 before it: target 0)
    ramp = p / rate
    want = np.interp(tc, [0.0, ramp, ramp + hold, 2 * ramp + hold], [0.0, p, p, 0.0])
    want[tc < 0] = 0.0
    assert np.any(tc > 0), tc
    assert np.allclose(target, want, rtol=1e-9, atol=1e-9 * p), np.c_[tc, target, want]
    # the yarns (and side planes) carry the fibers: their force on the fibers points up
    assert np.all(np.isfinite(yarn_f))


def test_overlap_guard_stops_overpressing(sheet: Path, fiberform_cmd: list[str],
                                          build_dir: Path) -> None:
    """The plate driven at 1 m/s to 1 um above the fabric top squeezes the fibers that lie on
    the yarn knuckles (the sheet's top is ~20 um above the fabric top) far beyond what the
    steric term can hold: the guard (5 % of the fiber thickness) ends the run."""
    out = sheet / "runs" / NAME / "press"
    shutil.rmtree(out, ignore_errors=True)
    proc = _press(sheet, fiberform_cmd, build_dir,
                  "{mode: velocity, plate_speed_m_s: 1.0, target_thickness_m: 1.0e-6, "
                  "overlap_limit: 0.05, hold_time_s: 1.0e-4, output_interval_s: 2.0e-6, "
                  "timestep_s: 1.0e-7}", "guard")
    assert proc.returncode == 1, proc.stdout[-2000:] + proc.stderr[-3000:]
    assert "overlap guard" in proc.stderr, proc.stderr[-3000:]
    assert "overlap_limit" in proc.stderr and "raise steric_cap_m" in proc.stderr
    # nothing of the press is left as a product (the stage writes atomically)
    for name in ("press.h5", "press.png", "curve.png", "report.md", "sheet.restart"):
        assert not (out / name).exists(), name


def test_overlap_action_stop_keeps_the_sheet_where_the_guard_trips(sheet: Path, fiberform_cmd: list[str],
                                                                    build_dir: Path) -> None:
    """The same over-pressing with ``overlap_action: stop`` (the thesis stopped pressing its
    circular-section sheets early, sec. 4.2): the stage succeeds, the plate stopped well above its
    1 um target, before the planned end of the motion, the pressed sheet is that of the last
    snapshot, and the record says why."""
    out = sheet / "runs" / NAME / "press"
    shutil.rmtree(out, ignore_errors=True)
    target, speed, dt = 1.0e-6, 1.0, 1.0e-7
    proc = _press(sheet, fiberform_cmd, build_dir,
                  f"{{mode: velocity, plate_speed_m_s: {speed}, target_thickness_m: {target}, "
                  "overlap_limit: 0.05, hold_time_s: 1.0e-4, output_interval_s: 2.0e-6, "
                  f"timestep_s: {dt}, overlap_action: stop}}", "guard_stop")
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    top, fab = _sheet_top(sheet), _fabric_top(sheet)
    with h5py.File(out / "press.h5", "r") as h:
        a, c = h["run"].attrs, h["curve"]
        assert a["stopped_by_guard"] == 1
        gap = float(c["plate_z"][-1] - a["fabric_top_z_m"])
        # the plate travelled from 5 um above the sheet top towards 1 um above the fabric top
        planned = (top + 5e-6 - fab - target) / speed
        assert float(c["time"][-1]) < planned - dt, (float(c["time"][-1]), planned)
        assert target + 1e-6 < gap < top - fab, (gap, top - fab)
        # the guard's measure (the fixes' overlaps) is not in the curve, but the dump's own
        # overlaps at the stop exceed the lay-down's by about the limit somewhere
        assert max(c["overlap_fiber"][-1], c["overlap_yarn"][-1], c["overlap_plate"][-1]) > 0.02
        x = h["sheet/x"][...]
    with h5py.File(sheet / "runs" / NAME / "laydown" / "laydown.h5", "r") as h:
        assert x.shape == h["sheet/x"].shape
    report = (out / "report.md").read_text()
    assert "stopped by the overlap guard" in report and "NOT reached" in report and "plate stopped at" not in report


@pytest.mark.parametrize("press, field", [
    ("{mode: velocity, plate_speed_m_s: -1.0, target_thickness_m: 1.0e-6}", "plate_speed_m_s"),
    ("{mode: velocity, target_thickness_m: 1.0e-3}", "target_thickness_m"),
    ("{mode: pressure}", "target_pressure_Pa"),
    ("{mode: velocity, target_thickness_m: 1.0e-5, target_pressure_Pa: 10.0}", "target_pressure_Pa"),
    ("{mode: pressure, target_pressure_Pa: 10.0, overlap_limit: 0.0}", "overlap_limit"),
    ("{mode: pressure, target_pressure_Pa: 10.0, output_interval_s: 1.0e-4, restart_interval_s: 5.0e-5}",
     "restart_interval_s"),
])
def test_bad_press_section_exits_2(sheet: Path, fiberform_cmd: list[str], build_dir: Path,
                                   press: str, field: str) -> None:
    out = sheet / "runs" / NAME / "press"
    before = sorted(p.name for p in out.iterdir()) if out.is_dir() else []
    proc = _press(sheet, fiberform_cmd, build_dir, press, "bad")
    assert proc.returncode == 2, proc.stdout[-2000:] + proc.stderr[-3000:]
    assert field in proc.stderr, proc.stderr[-2000:]
    after = sorted(p.name for p in out.iterdir()) if out.is_dir() else []
    assert after == before


def test_press_without_laydown_exits_2(tmp_path: Path, fiberform_cmd: list[str],
                                       build_dir: Path) -> None:
    (tmp_path / "s.yaml").write_text(BASE + "press: {mode: pressure, target_pressure_Pa: 10.0}\n")
    proc = _cli(fiberform_cmd, ["press", "s.yaml", "--build-dir", str(build_dir)], tmp_path)
    assert proc.returncode == 2, proc.stdout[-2000:] + proc.stderr[-3000:]
    assert re.search(r"laydown", proc.stderr), proc.stderr
    assert not (tmp_path / "runs" / NAME / "press").exists()


@pytest.mark.parametrize("mode", ["velocity", "pressure"])
def test_one_and_two_ranks_press_the_same_sheet(sheet: Path, fiberform_cmd: list[str],
                                                build_dir: Path, mode: str) -> None:
    """The same sheet, plate curve and (pressure mode) servo on 1 and 2 ranks: the plate's force and
    the servo's stiffness bound are sums over the ranks' contacts (each rank moves its own copy of
    the plate, so every rank must compute the same speed; until session 30 the bound was this
    rank's contacts' alone)."""
    top, fab = _sheet_top(sheet), _fabric_top(sheet)
    target = 0.5 * (top - fab)
    xs = []
    for ranks in (1, 2):
        press = (f"{{mode: velocity, plate_speed_m_s: 0.01, target_thickness_m: {target!r}, "
                 f"hold_time_s: 3.0e-4, output_interval_s: 1.0e-4, ranks: {ranks}}}" if mode == "velocity" else
                 "{mode: pressure, target_pressure_Pa: 2.0, pressure_rate_Pa_s: 4.0e+3, hold_time_s: 4.0e-4, "
                 "release_time_s: 3.0e-4, plate_speed_m_s: 0.02, output_interval_s: 1.0e-4, "
                 f"ranks: {ranks}}}")
        proc = _press(sheet, fiberform_cmd, build_dir, press, f"ranks{ranks}_{mode}")
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
        with h5py.File(sheet / "runs" / NAME / "press" / "press.h5", "r") as h:
            xs.append((h["sheet/x"][...], h["sheet/fiber_id"][...], h["curve/plate_force"][...],
                       h["curve/plate_z"][...]))
    (x1, id1, f1, z1), (x2, id2, f2, z2) = xs
    assert np.array_equal(id1, id2)
    assert np.max(np.abs(x1 - x2)) < 1e-9, np.max(np.abs(x1 - x2))
    assert np.max(np.abs(z1 - z2)) < 1e-9, np.max(np.abs(z1 - z2))
    scale = max(1e-12, float(np.max(np.abs(f1))))
    assert np.max(np.abs(f1 - f2)) <= 1e-6 * scale, (np.max(np.abs(f1 - f2)), scale)
    assert math.isfinite(scale)


@pytest.mark.parametrize("mode", ["velocity", "pressure"])
def test_killed_press_resumes_to_the_same_sheet(sheet: Path, fiberform_cmd: list[str], build_dir: Path,
                                                mode: str) -> None:
    """Restart files every 2 output intervals (press.<step>.restart); a press killed (SIGKILL to its
    process group) late in its run and continued with ``--resume`` ends as the uninterrupted one,
    to the bit: every curve point (plate height, pressure) and node of every snapshot. (The plate
    is defined again at every restart step in both runs, at the stage's height: without that the
    fix's sum of steps and the resumed definition differ in the last bits, and the contacts grow
    it: 3e-11 m at the end of the velocity press, 2e-9 m and 0.085 Pa in the pressure press's
    servo; docs/stages/press.md, "Resuming".) Velocity mode resumes from its last complete restart
    file; pressure mode only from one before the servo took over (its state is not in the file), or
    it starts over."""
    from cli_helpers import terminate_when
    from fiberform.liggghts_log import read_dump

    top, fab = _sheet_top(sheet), _fabric_top(sheet)
    press = (f"{{mode: velocity, plate_speed_m_s: 0.01, target_thickness_m: {0.5 * (top - fab)!r}, "
             "hold_time_s: 5.0e-4, output_interval_s: 1.0e-4, restart_interval_s: 2.0e-4}"
             if mode == "velocity" else
             "{mode: pressure, target_pressure_Pa: 2.0, pressure_rate_Pa_s: 4.0e+3, hold_time_s: 4.0e-4, "
             "release_time_s: 3.0e-4, plate_speed_m_s: 0.02, output_interval_s: 1.0e-4, restart_interval_s: 2.0e-4}")
    out = sheet / "runs" / NAME / "press"

    def result() -> dict[str, np.ndarray]:
        with h5py.File(out / "press.h5", "r") as h:
            a = h["run"].attrs
            got = {"x": h["sheet/x"][...], "id": h["sheet/fiber_id"][...], "step": h["curve/step"][...],
                   "z": h["curve/plate_z"][...], "p": h["curve/pressure"][...],
                   "resumed": np.array(a["resumed_from_step"]),
                   "servo": np.array([a.get("servo_start_time_s", np.nan), a.get("servo_start_z_m", np.nan)])}
        frames = {fr.step: fr for fr in read_dump(out / "work" / "traj.dump")}
        got.update({f"nodes{st}": np.stack([fr.columns[c] for c in "xyz"], 1) for st, fr in frames.items()})
        return got

    proc = _press(sheet, fiberform_cmd, build_dir, press, f"resume_{mode}")
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    ref = result()
    assert int(ref["resumed"]) == -1
    steps = sorted(int(p.name.split(".")[1]) for p in (out / "work").glob("press.*.restart"))
    assert steps and all(s % 200 == 0 for s in steps) and steps[-1] >= 1000, steps
    last = steps[-1]
    shutil.rmtree(out)
    rc = terminate_when([*fiberform_cmd, "press", f"resume_{mode}.yaml", "--build-dir", str(build_dir)],
                        sheet, out / "work" / f"press.{last}.restart", timeout_s=600, kill_group=True)
    assert rc != 0 and not (out / "press.h5").exists()
    # `fiberform status` names the latest restart file and the press's largest length (velocity
    # mode: its length; pressure mode: the approach may end before its largest travel)
    status = _cli(fiberform_cmd, ["status", f"resume_{mode}.yaml", "--build-dir", str(build_dir)], sheet)
    line = next(ln for ln in status.stdout.splitlines() if ln.split()[:1] == ["press"])
    found = re.search(r"restart files to step (\d+) of at most (\d+)", line)
    assert found and "--resume" in line, line
    assert int(found.group(1)) == last, line
    assert (int(found.group(2)) == int(ref["step"][-1]) if mode == "velocity"
            else int(found.group(2)) >= int(ref["step"][-1])), line
    res = _cli(fiberform_cmd, ["press", f"resume_{mode}.yaml", "--resume", "--build-dir", str(build_dir)], sheet)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-3000:]
    got = result()
    start = int(got["resumed"])
    if mode == "velocity":
        assert start >= last - 200 and start % 200 == 0, (start, last)  # its last complete one
    else:
        servo_step = round(float(ref["servo"][0]) / 1e-6)  # laydown.timestep_s 1e-6
        # the last restart file before the servo took over (none: it starts over)
        before = (servo_step - 1) // 200 * 200
        assert start == (before if before > 0 else -1), (start, servo_step)
    assert sorted(got) == sorted(ref)  # the same snapshots
    for key in ref:
        if key != "resumed":
            assert np.array_equal(got[key], ref[key], equal_nan=True), (key, np.max(np.abs(got[key] - ref[key])))


def test_probe_step_continues_the_press(sheet: Path, fiberform_cmd: list[str], build_dir: Path) -> None:
    """bench/press/probe_step.py (docs/bench/press.md section 4) resumes a press from its restart
    file with the stage's own input: with the press's own settings it reaches, 100 steps after the
    restart step, the plate force the press itself logged there (the same printed digits); a variant with
    split_memory runs too and reports its per-step rows; a bad variant exits 2 naming the key."""
    import json
    import os

    top, fab = _sheet_top(sheet), _fabric_top(sheet)
    press = (f"{{mode: velocity, plate_speed_m_s: 0.01, target_thickness_m: {0.5 * (top - fab)!r}, "
             "hold_time_s: 5.0e-4, output_interval_s: 1.0e-4, restart_interval_s: 2.0e-4}")
    proc = _press(sheet, fiberform_cmd, build_dir, press, "probe")
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    log = (sheet / "runs" / NAME / "press" / "work" / "log.fiberdem").read_text()
    logged = {int(w[0]): float(w[4]) for w in (ln.split() for ln in log.splitlines())
              if len(w) == 17 and w[0].isdigit()}  # step and plate force fz (press.COLUMNS)
    assert 300 in logged, sorted(logged)[:10]
    script = Path(__file__).resolve().parents[1] / "bench" / "press" / "probe_step.py"
    env = {**os.environ, "FIBERFORM_BUILD": str(build_dir)}
    out = sheet / "probe.json"
    run = subprocess.run([sys.executable, str(script), "probe.yaml", "--step", "200", "--time", "1e-4",
                          "--variant", "timestep=1e-6", "--variant", "timestep=1e-6,split_memory=5",
                          "--out", str(out)], cwd=sheet, env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-3000:]
    doc = json.loads(out.read_text())
    plain, memory = doc["variants"]
    assert plain["rows"]["step"] == [float(k) for k in range(201, 301)]
    assert len(memory["rows"]["step"]) == 100
    assert plain["start_depth"]["max"] == 0
    assert plain["plate_force_z_N_last"] == logged[300], (plain["plate_force_z_N_last"], logged[300])
    bad = subprocess.run([sys.executable, str(script), "probe.yaml", "--step", "200", "--variant", "newton_max=0"],
                         cwd=sheet, env=env, capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "newton_max" in bad.stderr and "[1, 1000]" in bad.stderr, bad.stderr


def test_permeability_after_the_press_reads_the_pressed_sheet(sheet: Path, fiberform_cmd: list[str],
                                                               build_dir: Path) -> None:
    """With press and permeability sections, stage permeability-press puts the PRESSED sheet
    (press.h5 /sheet) on the fabric, in its own folder (the OpenFOAM run itself is tested in
    tests/test_permeability.py; here the geometry it is given)."""
    import os

    from fiberform.scene import load_scene
    from fiberform.stages import STAGES
    from fiberform.stages._stage import StageContext

    top, fab = _sheet_top(sheet), _fabric_top(sheet)
    press = (f"{{mode: velocity, plate_speed_m_s: 0.01, target_thickness_m: {0.5 * (top - fab)!r}, "
             "hold_time_s: 3.0e-4, output_interval_s: 1.0e-4}")
    proc = _press(sheet, fiberform_cmd, build_dir, press, "perm")
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    path = sheet / "perm2.yaml"
    path.write_text(BASE + f"press: {press}\npermeability: {{mode: subgrid}}\n")
    cwd = os.getcwd()
    try:
        os.chdir(sheet)
        scene = load_scene(path)
        ctx = StageContext(scene=scene, scene_path=path, build_dir=build_dir)
        stage = STAGES["permeability-press"]
        assert stage.stage_dir(ctx).name == "permeability-press"
        assert STAGES["permeability"].stage_dir(ctx).name == "permeability-laydown"
        geo = stage.geometry(ctx)
        plain = STAGES["permeability"].geometry(ctx)
    finally:
        os.chdir(cwd)
    with h5py.File(sheet / "runs" / NAME / "press" / "press.h5", "r") as h:
        x, offs = h["sheet/x"][...], h["sheet/offsets"][...]
    got = np.concatenate([c.points for c in geo.fiber_chains])
    assert len(geo.fiber_chains) == len(offs) - 1
    assert np.array_equal(got, x)
    with h5py.File(sheet / "runs" / NAME / "laydown" / "laydown.h5", "r") as h:
        assert np.array_equal(np.concatenate([c.points for c in plain.fiber_chains]), h["sheet/x"][...])
