# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage laydown (issue 10): restart files, `fiberform laydown --resume` after a kill, and the
lay-down on two MPI ranks. A tiny scene (6 fibers, real stiffness and inertia, implicit, 1 us) runs
uninterrupted to max_time_s; then the lay-down is run again, killed (SIGKILL to the whole process
group) after its second restart file, and resumed: the resumed sheet equals the uninterrupted one
to the bit (measured in session 29; before it was held to 1e-9 m); the same lay-down on 2 ranks
(the box split in x or y, fibers across the split) equals the 1-rank sheet within TOL_RANKS, with
the same mass accounting."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pytest

from cli_helpers import processes_under, terminate_when
from laydown_scenes import tiny_laydown_scene

pytestmark = pytest.mark.system

TOL_RANKS = 1e-9   # m (measured: identical; each fiber is solved whole on one rank)


def write_four_fibers(path: Path) -> None:
    """A nodes file of 4 fibers (IDs 1-4) of 2 nodes each: atom fiber node count ..."""
    path.write_text("# header\n" + "".join(f"{2 * f + k + 1} {f + 1} {k} 2 1e-5 1e-5 0 0\n"
                                            for f in range(4) for k in range(2)))


def snapshot(step: int, fibers: list[int]) -> str:
    """A dump snapshot of the 2-node fibers ``fibers`` (1-based IDs) of :func:`write_four_fibers`."""
    rows = [f"{2 * (f - 1) + k + 1} 1e-12 0 0 0 {f} {k}" for f in fibers for k in range(2)]
    return (f"ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n{len(rows)}\n"
            "ITEM: BOX BOUNDS ff ff ff\n0 1\n0 1\n0 1\nITEM: ATOMS id mass x y z f_beam[1] f_beam[2]\n"
            + "".join(r + "\n" for r in rows))


def _scene(work: Path, out: str, ranks: int) -> Path:
    p = work / f"{out}.yaml"
    p.write_text(tiny_laydown_scene("resume_laydown", out, ranks, 0.006))
    return p


def _sheet(h5: Path) -> tuple[np.ndarray, np.ndarray]:
    with h5py.File(h5, "r") as h:
        return h["sheet/x"][...], h["sheet/fiber_id"][...]


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory, build_dir: Path,
              fiberform_cmd: list[str]) -> tuple[Path, Path]:
    """The uninterrupted 1-rank run (all stages)."""
    if not (build_dir / "bin" / "fiberdem").is_file():
        pytest.skip("fiberdem not built")
    work = tmp_path_factory.mktemp("resume")
    scene = _scene(work, "a", 1)
    proc = subprocess.run([*fiberform_cmd, "run", scene.name, "--build-dir", str(build_dir)],
                          cwd=work, capture_output=True, text=True, errors="replace", timeout=900)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    return work, scene


def test_restart_files_are_written(reference: tuple[Path, Path]) -> None:
    work, _ = reference
    names = sorted(p.name for p in (work / "runs/a/laydown/work").glob("laydown.*.restart"))
    # every 1 ms of 6 ms: steps 1000 ... 6000
    assert names == sorted(f"laydown.{k * 1000}.restart" for k in range(1, 7)), names


@pytest.mark.parametrize("how", ["SIGKILL", "SIGTERM"])
def test_killed_laydown_resumes_to_the_same_sheet(reference: tuple[Path, Path], build_dir: Path,
                                                  fiberform_cmd: list[str], how: str) -> None:
    """SIGKILL to the whole process group (a node failure), or SIGTERM to fiberform alone (a
    batch time limit: fiberform stops fiberdem and its ranks itself, records failed, exits 143)."""
    work, scene = reference
    ref_copy = work / "reference.h5"
    if not ref_copy.is_file():
        shutil.copyfile(work / "runs/a/laydown/laydown.h5", ref_copy)
    x_ref, id_ref = _sheet(ref_copy)
    (work / "runs/a/laydown/laydown.h5").unlink(missing_ok=True)
    lw = work / "runs/a/laydown/work"
    shutil.rmtree(lw, ignore_errors=True)  # earlier restart files must not be mistaken for new ones
    rc = terminate_when([*fiberform_cmd, "laydown", scene.name, "--force", "--build-dir", str(build_dir)], work,
                        lw / "laydown.3000.restart", timeout_s=600, kill_group=how == "SIGKILL")
    if how == "SIGTERM":
        assert rc == 143, rc
        state = (work / "runs/a/laydown/stage-state.json").read_text()
        assert '"failed"' in state and "SIGTERM" in state, state
        alive = processes_under(work)
        assert not alive, f"left running after SIGTERM: {alive}"
    assert not (work / "runs/a/laydown/laydown.h5").exists()  # no product of a killed run
    # a plain rerun does not discard the killed run's restart files: exit 2, nothing removed
    kept = sorted(p.name for p in lw.iterdir())
    plain = subprocess.run([*fiberform_cmd, "laydown", scene.name, "--build-dir", str(build_dir)], cwd=work,
                           capture_output=True, text=True, errors="replace", timeout=300)
    assert plain.returncode == 2 and "--resume` continues it" in plain.stderr, plain.stderr[-2000:]
    assert sorted(p.name for p in lw.iterdir()) == kept
    res = subprocess.run([*fiberform_cmd, "laydown", scene.name, "--resume", "--build-dir",
                          str(build_dir)], cwd=work, capture_output=True, text=True,
                         errors="replace", timeout=900)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-3000:]
    with h5py.File(work / "runs/a/laydown/laydown.h5", "r") as h:
        start = int(h["run"].attrs["resumed_from_step"])
        steps = h["snapshots/step"][...]
    assert 1000 <= start <= 3000 and start % 1000 == 0, start  # from a complete restart file
    with h5py.File(work / "runs/a/laydown/laydown.h5", "r") as h:
        run, elapsed = dict(h["run"].attrs), float(h.attrs["elapsed_s"])
    # the killed part's time up to the restart step counts (wall.earlier.json)
    assert run["wall_time_earlier_parts_s"] > 0.0, run
    assert run["wall_time_s"] == pytest.approx(run["wall_time_this_part_s"] + run["wall_time_earlier_parts_s"])
    assert elapsed > run["wall_time_earlier_parts_s"]
    assert list(steps) == sorted(set(steps.tolist())), "snapshots repeated or out of order"
    assert steps[-1] == 6000
    x, ids = _sheet(work / "runs/a/laydown/laydown.h5")
    assert np.array_equal(ids, id_ref)
    # identical to the bit: the restart files are exact and the lay-down's fixes keep no state
    # outside them that the resumed run would set otherwise (a press needed its plate defined
    # again at every restart step for this: docs/stages/press.md, "Resuming")
    assert np.array_equal(x, x_ref), np.abs(x - x_ref).max()


def test_a_laydown_goes_on_with_another_max_time(reference: tuple[Path, Path], build_dir: Path,
                                                fiberform_cmd: list[str]) -> None:
    """A lay-down that ended at its max_time_s (3 ms, not settled) goes on from its own restart
    files when max_time_s is raised to 6 ms and --resume is given (the restart identity leaves the
    end time out): it resumes from a restart file of the first run, not from step 0, and ends with
    the sheet of the uninterrupted 6 ms run, to the bit; a plain rerun with the new end time
    refuses to discard those restart files (exit 2). Lowered again to 2 ms, --resume ends it from
    the restart file before the new end (the one at the end itself would leave nothing to run)."""
    work, _ = reference
    ref = work / "reference.h5"
    if not ref.is_file():
        shutil.copyfile(work / "runs/a/laydown/laydown.h5", ref)
    x_ref, id_ref = _sheet(ref)
    for stage in ("fibers", "fabric", "flow"):  # the same upstream products (their hashes match)
        shutil.copytree(work / "runs/a" / stage, work / "runs/c" / stage)
    scene = work / "c.yaml"

    def lay(max_time_s: float, *options: str) -> subprocess.CompletedProcess[str]:
        scene.write_text(tiny_laydown_scene("resume_laydown", "c", 1, max_time_s))
        return subprocess.run([*fiberform_cmd, "laydown", scene.name, *options, "--build-dir", str(build_dir)],
                              cwd=work, capture_output=True, text=True, errors="replace", timeout=900)

    def ran(h5: Path) -> tuple[int, int]:
        with h5py.File(h5, "r") as h:
            return int(h["run"].attrs["resumed_from_step"]), int(h["snapshots/step"][-1])

    first = lay(0.003)
    assert first.returncode == 0, first.stdout[-2000:] + first.stderr[-3000:]
    product = work / "runs/c/laydown/laydown.h5"
    assert ran(product) == (-1, 3000)
    plain = lay(0.006)
    assert plain.returncode == 2 and "--resume` continues it" in plain.stderr, plain.stderr[-2000:]
    longer = lay(0.006, "--resume")
    assert longer.returncode == 0, longer.stdout[-2000:] + longer.stderr[-3000:]
    assert ran(product) == (2000, 6000)  # the last restart file with a snapshot after it
    x, ids = _sheet(product)
    assert np.array_equal(ids, id_ref) and np.array_equal(x, x_ref), np.abs(x - x_ref).max()
    shorter = lay(0.002, "--resume")
    assert shorter.returncode == 0, shorter.stdout[-2000:] + shorter.stderr[-3000:]
    assert ran(product) == (1000, 2000)


def test_two_ranks_lay_down_the_same_sheet(reference: tuple[Path, Path], build_dir: Path,
                                           fiberform_cmd: list[str]) -> None:
    if (os.cpu_count() or 1) < 2:
        pytest.skip("needs 2 cores")
    work, _ = reference
    if not (work / "reference.h5").is_file():
        shutil.copyfile(work / "runs/a/laydown/laydown.h5", work / "reference.h5")
    x_ref, id_ref = _sheet(work / "reference.h5")
    scene = _scene(work, "b", 2)
    proc = subprocess.run([*fiberform_cmd, "run", scene.name, "--build-dir", str(build_dir)],
                          cwd=work, capture_output=True, text=True, errors="replace", timeout=900)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    x, ids = _sheet(work / "runs/b/laydown/laydown.h5")
    assert np.array_equal(ids, id_ref)
    with h5py.File(work / "runs/b/laydown/laydown.h5", "r") as h:
        assert int(h["run"].attrs["ranks"]) == 2
        offsets = h["sheet/offsets"][...]
        masses = [float(h["accounting"][k][()]) for k in ("sheet_mass", "removed_mass")]
    with h5py.File(work / "reference.h5", "r") as h:
        assert masses == [float(h["accounting"][k][()]) for k in ("sheet_mass", "removed_mass")]
    log = (work / "runs/b/laydown/work/log.fiberdem").read_text()
    grid = "1 by 2 by 1" if "1 by 2 by 1 MPI" in log else "2 by 1 by 1"
    assert f"{grid} MPI processor grid" in log  # the sheet plane is split, not z
    axis = 1 if grid == "1 by 2 by 1" else 0
    across = [np.ptp(np.sign(x[lo:hi, axis] - 0.5e-3)) > 0 for lo, hi in zip(offsets[:-1], offsets[1:])]
    assert any(across), "no fiber spans both ranks' sub-domains"
    assert np.abs(x - x_ref).max() < TOL_RANKS, np.abs(x - x_ref).max()


def test_no_fiber_passes_through_another(reference: tuple[Path, Path]) -> None:
    """Fiber-fiber contact inside the Newton solves (laydown.fiber_contact newton, the default):
    at every snapshot the smallest surface gap between elements of two fibers stays above -5 % of
    the radius (the law's own overlaps are nanometres; a pass-through is -radius and below), and
    fibers did touch (a gap below the law's 50 nm range at some snapshot)."""
    work, _ = reference
    h5 = work / "reference.h5" if (work / "reference.h5").is_file() else work / "runs/a/laydown/laydown.h5"
    with h5py.File(h5, "r") as h:
        gaps = h["snapshots/min_fiber_fiber_gap"][...]
        assert "implicit_force newton" in str(h["run"].attrs["fiber_contact"])
    r = 10e-6
    assert gaps.min() > -0.05 * r, gaps.min()
    assert gaps.min() < 50e-9, gaps.min()


def test_resume_after_a_removal_lists_only_the_fibers_left(tmp_path: Path) -> None:
    """A lay-down resumed from a restart written after fix fiber/remove took fibers out: the nodes
    file handed to fix fiber/beam lists the fibers left (it refuses atoms the restart file lacks);
    removals after the restart step are not applied (they happen again in the resumed run)."""
    from fiberform.stages.laydown import EARLIER_LOG, LOG_NAME, nodes_left, prepare_resume

    work = tmp_path / "work"
    work.mkdir()
    src = tmp_path / "fibers.nodes"
    write_four_fibers(src)
    (work / "traj.dump").write_text("")
    (work / LOG_NAME).write_text("fix fiber/remove: step 1000 removed fiber(s) 2\n"
                                 "fix fiber/remove: step 3000 removed fiber(s) 4\n")
    prepare_resume(work, 2000)
    assert "step 1000" in (work / EARLIER_LOG).read_text()
    nodes_left(work, src)
    rows = [ln.split() for ln in (work / "fibers.nodes").read_text().splitlines() if not ln.startswith("#")]
    assert sorted({int(r[1]) for r in rows}) == [1, 3, 4]
    assert len(rows) == 6


def test_resumed_runs_count_the_time_of_the_parts_before(tmp_path: Path) -> None:
    """wall.earlier.json: at each resume the killed part's Loop times up to the restart step are
    added to the parts before (its work after the restart step is redone: not counted); a resume
    back behind a step already counted makes the earlier time unknown; a run from step 0 has
    none."""
    import json

    from fiberform.liggghts_restart import PREPARED_STEP
    from fiberform.stages.laydown import LOG_NAME, earlier_wall, prepare_resume

    def log(*runs: tuple[int, int, float]) -> str:
        return "".join(f"Step Atoms\n {a} 8\n {b} 8\nLoop time of {t} on 2 procs for {b - a} steps with 8 atoms\n"
                       for a, b, t in runs)

    work = tmp_path / "work"
    work.mkdir()
    (work / "traj.dump").write_text("")
    (work / PREPARED_STEP).write_text(json.dumps({"resume_step": None}))
    assert earlier_wall(work) == 0.0
    # the first part: runs to 1000, 2000, 3000 (restart file at 2000), killed during the 4th
    (work / LOG_NAME).write_text(log((0, 1000, 10.0), (1000, 2000, 20.0), (2000, 3000, 40.0)) + "Step Atoms\n 3000 8\n")
    prepare_resume(work, 2000)
    (work / PREPARED_STEP).write_text(json.dumps({"resume_step": 2000}))
    assert earlier_wall(work) == 30.0
    # the second part from 2000: runs to 3000 and 4000, killed; resumed from its 4000 restart
    (work / LOG_NAME).write_text(log((2000, 3000, 5.0), (3000, 4000, 7.0), (4000, 5000, 9.0)))
    prepare_resume(work, 4000)
    (work / PREPARED_STEP).write_text(json.dumps({"resume_step": 4000}))
    assert earlier_wall(work) == 42.0
    # back behind 4000: the count would include redone work
    (work / LOG_NAME).write_text(log((4000, 4500, 1.0)))
    prepare_resume(work, 3000)
    (work / PREPARED_STEP).write_text(json.dumps({"resume_step": 3000}))
    assert earlier_wall(work) is None


def test_resume_recovers_a_removal_the_log_lost(tmp_path: Path) -> None:
    """A killed run whose log lost a removal line (a buffered log: the restart file was written,
    the line was not): the removal is recovered from the snapshots, at the step of the first
    snapshot without the fiber, and the nodes file of the resumed run lists only the fibers the
    restart file holds. A log that reports a fiber removed which the snapshot still holds is an
    error, not silently merged."""
    from fiberform.errors import StageError
    from fiberform.stages.laydown import EARLIER_LOG, LOG_NAME, TRAJ_NAME, nodes_left, prepare_resume

    work = tmp_path / "work"
    work.mkdir()
    src = tmp_path / "fibers.nodes"
    write_four_fibers(src)

    dump = (snapshot(0, [1, 2, 3, 4]) + snapshot(1000, [1, 3, 4]) + snapshot(2000, [1, 3, 4])
            + snapshot(3000, [1, 4]) + snapshot(4000, [1]))
    (work / TRAJ_NAME).write_text(dump)
    # fiber 2 logged at 1000; fiber 3's line (step 3000) lost; fiber 4 (after the restart) not reached
    (work / LOG_NAME).write_text("fix fiber/remove: step 1000 removed fiber(s) 2\n")
    prepare_resume(work, 3000, src)
    earlier = (work / EARLIER_LOG).read_text()
    assert "step 1000 removed fiber(s) 2\n" in earlier
    assert "step 3000 removed fiber(s) 3 (recovered from the snapshots)" in earlier
    assert "fiber(s) 4" not in earlier
    assert (work / TRAJ_NAME).read_text() == snapshot(0, [1, 2, 3, 4]) + snapshot(1000, [1, 3, 4]) + snapshot(2000, [1, 3, 4])
    nodes_left(work, src)
    rows = [ln.split() for ln in (work / "fibers.nodes").read_text().splitlines() if not ln.startswith("#")]
    assert sorted({int(r[1]) for r in rows}) == [1, 4]

    # a log that contradicts the snapshots
    (work / EARLIER_LOG).unlink()
    (work / TRAJ_NAME).write_text(dump)
    (work / LOG_NAME).write_text("fix fiber/remove: step 1000 removed fiber(s) 1\n")
    with pytest.raises(StageError, match="holds them"):
        prepare_resume(work, 3000, src)


def test_a_resume_killed_before_its_first_snapshot_resumes_again(tmp_path: Path) -> None:
    """A resumed lay-down killed before it wrote its first snapshot (the dump was cut back to the
    restart step): the next resume starts from the same restart file again (it was complete: the
    first resume started from it), keeps it and the removals up to it, and does not mistake a
    removal logged between the last snapshot and the restart step for a contradiction. (Session
    19: the case-C run lost its 10 ms restart file this way and went back to 8 ms.)"""
    import json

    from fiberform.liggghts_restart import PREPARED_STEP, RESUME_STATE
    from fiberform.stages.laydown import EARLIER_LOG, LOG_NAME, TRAJ_NAME, nodes_left, prepare_resume, resume_point

    work = tmp_path / "work"
    work.mkdir()
    src = tmp_path / "fibers.nodes"
    write_four_fibers(src)

    hashes = {"scene": "sha256:1"}
    (work / RESUME_STATE).write_text(json.dumps(hashes))
    (work / TRAJ_NAME).write_text(snapshot(0, [1, 2, 3, 4]) + snapshot(2000, [1, 2, 3, 4])
                                  + snapshot(4000, [1, 2, 4]) + snapshot(5000, [1, 2]))
    (work / LOG_NAME).write_text("fix fiber/remove: step 3000 removed fiber(s) 3\n"
                                 "fix fiber/remove: step 5000 removed fiber(s) 4\n")
    for step in (2000, 3000):
        (work / f"laydown.{step}.restart").write_text("restart\n")
    (work / PREPARED_STEP).write_text(json.dumps({"resume_step": None}))

    # the first resume: from 3000 (a snapshot after it exists)
    assert resume_point(work, hashes) == 3000
    prepare_resume(work, 3000, src)
    earlier = (work / EARLIER_LOG).read_text()
    assert earlier == "fix fiber/remove: step 3000 removed fiber(s) 3\n", earlier
    assert (work / TRAJ_NAME).read_text() == snapshot(0, [1, 2, 3, 4]) + snapshot(2000, [1, 2, 3, 4])
    (work / PREPARED_STEP).write_text(json.dumps({"resume_step": 3000}))
    # ... killed at once: its log holds no line of fix fiber/remove, the dump no new snapshot
    (work / LOG_NAME).write_text("LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0)\nReading restart file ...\n")

    # the second resume: from 3000 again, not 2000, and the 3000 restart file stays
    assert resume_point(work, hashes) == 3000
    prepare_resume(work, 3000, src)
    assert (work / "laydown.3000.restart").is_file()
    assert (work / EARLIER_LOG).read_text() == earlier
    nodes_left(work, src)
    rows = [ln.split() for ln in (work / "fibers.nodes").read_text().splitlines() if not ln.startswith("#")]
    assert sorted({int(r[1]) for r in rows}) == [1, 2, 4]


def test_status_says_how_far_a_resume_continues_from(tmp_path: Path, fiberform_cmd: list[str]) -> None:
    """``fiberform status`` of a killed lay-down with restart files names the latest one and the
    run's largest length (6 ms at 1 us: 6000 steps), and that ``--resume`` continues from there; a failed
    stage without restart files says nothing of it."""
    import json

    (tmp_path / "s.yaml").write_text(tiny_laydown_scene("status_resume", "s", 1, 0.006))
    work = tmp_path / "runs/s/laydown/work"
    work.mkdir(parents=True)
    (work.parent / "stage-state.json").write_text(json.dumps({
        "state": "failed", "stage": "laydown", "started_utc": "2026-01-01T00:00:00+00:00",
        "failed_utc": "2026-01-01T01:00:00+00:00", "error": "terminated (SIGTERM)"}))

    def laydown_line() -> str:
        proc = subprocess.run([*fiberform_cmd, "status", "s.yaml"], cwd=tmp_path, capture_output=True, text=True,
                              timeout=120)
        assert proc.returncode == 0, proc.stderr[-2000:]
        return next(line for line in proc.stdout.splitlines() if line.split()[:1] == ["laydown"])

    assert "restart" not in laydown_line()
    for step in (2000, 4000):
        (work / f"laydown.{step}.restart").write_text("restart\n")
    line = laydown_line()
    assert "failed" in line and "restart files to step 4000 of at most 6000" in line and "--resume" in line, line
