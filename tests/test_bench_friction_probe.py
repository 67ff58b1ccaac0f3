# SPDX-License-Identifier: GPL-3.0-or-later
"""bench/laydown/probe_friction.py writes the lay-down stage's own resumed input with the probe's
friction setting (laydown.friction_coefficient, laydown.friction_stick), the solver counters and
the final-state dump, refuses bad --builds/--ranks/--repeat/--parallel/--concurrency before
anything runs, and fiberform.provenance.append_result_rows keeps earlier rows. No binaries needed
but for the system test: a tiny lay-down (6 fibers, 2 ms) probed for 100 steps with two builds
(the build and a copy of it) on 1 and 2 ranks, alternating, twice: equal final-state hashes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from bench_scripts import load_bench_script
from laydown_scenes import tiny_laydown_scene
from fiberform._versions import build_revision
from fiberform.provenance import append_result_rows

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def probe() -> Any:
    return load_bench_script("bench/laydown/probe_friction.py", "probe_friction")


@pytest.fixture()
def run(tmp_path: Path) -> Path:
    """A run folder holding the shipped case-A scene as a lay-down run would (2 ranks, newton)."""
    data = yaml.safe_load((ROOT / "scenes" / "thesis" / "case-A-circular.yaml").read_text())
    data["laydown"]["fiber_contact"] = "newton"
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(data))
    return tmp_path


def fix_lines(text: str, style: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("fix ") and f" {style} " in line]


def test_stick_setting_reaches_every_static_body(probe: Any, run: Path) -> None:
    text = probe.probe_input(run, 4000, 300, 50, 0.5, 10.0)
    bodies = fix_lines(text, "wall/fiber/yarns") + fix_lines(text, "wall/fiber/dlvo")
    assert len(bodies) == 5  # yarns and four side planes
    for line in bodies:
        assert line.endswith("friction 0.5 friction_stick 10.0"), line
    assert "read_restart laydown.4000.restart" in text.splitlines()
    # 300 steps in runs of 50 after step 4000, the solver counters in the thermo output
    assert sum(1 for line in text.splitlines() if line.startswith("run 50")) == 6
    thermo = [line for line in text.splitlines() if line.startswith("thermo_style")]
    assert thermo == ["thermo_style custom step atoms f_beam[14] f_beam[15] f_beam[18] f_beam[19] f_beam[20] f_beam[21]"]
    assert fix_lines(text, "fiber/beam")  # the fibers are defined before any contact


def test_frictionless_setting_has_no_stick(probe: Any, run: Path) -> None:
    text = probe.probe_input(run, 4000, 300, 50, 0.0, 100.0)
    for line in fix_lines(text, "wall/fiber/yarns") + fix_lines(text, "wall/fiber/dlvo"):
        assert line.endswith("friction 0.0"), line


def test_anderson_reaches_the_beam_fix(probe: Any, run: Path) -> None:
    """--anderson M puts `anderson M` on fix fiber/beam; without it the keyword is absent."""
    beam = fix_lines(probe.probe_input(run, 4000, 300, 50, 0.5, 100.0, probe.probe_fields(anderson=3)), "fiber/beam")
    assert len(beam) == 1 and " anderson 3" in beam[0], beam
    plain = fix_lines(probe.probe_input(run, 4000, 300, 50, 0.5, 100.0), "fiber/beam")
    assert " anderson " not in plain[0], plain


def test_landing_reaches_the_beam_fix(probe: Any, run: Path) -> None:
    """--landing predict puts `landing predict` on fix fiber/beam; limit (the default) writes nothing."""
    beam = fix_lines(probe.probe_input(run, 4000, 300, 50, 0.5, 100.0, probe.probe_fields(landing="predict")),
                     "fiber/beam")
    assert len(beam) == 1 and " landing predict" in beam[0], beam
    plain = fix_lines(probe.probe_input(run, 4000, 300, 50, 0.5, 100.0, probe.probe_fields(landing="limit")),
                      "fiber/beam")
    assert " landing " not in plain[0], plain


def test_tolerance_and_timestep_reach_the_input(probe: Any, run: Path) -> None:
    """--tolerance T and --timestep DT reach fix fiber/beam's newton_tol and the timestep command."""
    fields = probe.probe_fields(tolerance=1e-5, timestep=2e-6)
    assert fields == {"laydown.newton_tolerance": 1e-5, "laydown.timestep_s": 2e-6}
    text = probe.probe_input(run, 4000, 300, 50, 0.5, 200.0, fields)
    beam = fix_lines(text, "fiber/beam")
    assert " newton_tol 1e-05 " in beam[0] + " ", beam
    assert any(line.split() == ["timestep", "2e-06"] for line in text.splitlines()), text
    plain = probe.probe_input(run, 4000, 300, 50, 0.5, 200.0)
    assert " newton_tol 1e-05 " not in fix_lines(plain, "fiber/beam")[0] + " "
    assert not any(line.split() == ["timestep", "2e-06"] for line in plain.splitlines())


def test_probe_must_fit_the_chunks(probe: Any, run: Path) -> None:
    with pytest.raises(SystemExit, match="multiples"):
        probe.probe_input(run, 4000, 310, 50, 0.5, 10.0)
    with pytest.raises(SystemExit, match="FRICTION:STICK"):
        probe.parse_setting("half")


def test_append_result_rows_keeps_earlier_rows(tmp_path: Path) -> None:
    out = tmp_path / "results" / "probe.json"
    append_result_rows(out, [{"a": 1}])
    append_result_rows(out, [{"a": 2}, {"a": 3}])
    assert json.loads(out.read_text()) == {"rows": [{"a": 1}, {"a": 2}, {"a": 3}]}
    assert not list(out.parent.glob("*.in_progress"))


SCRIPT = ROOT / "bench" / "laydown" / "probe_friction.py"
#: a tiny lay-down with restart files at steps 1000 and 2000 (2 ms)
TINY = tiny_laydown_scene("probe_builds", "a", 1, 0.002)


def run_script(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True,
                          errors="replace", timeout=600, check=False)


def test_probe_ends_with_the_final_state_dump(probe: Any, run: Path) -> None:
    """The last line writes every node's id, position and velocity with 17 digits, sorted by id."""
    last = probe.probe_input(run, 4000, 300, 50, 0.5, 10.0).splitlines()[-1]
    assert last == ('write_dump all custom final.dump id x y z vx vy vz modify sort id format '
                    '"%d %.17g %.17g %.17g %.17g %.17g %.17g"'), last


def test_combinations_alternate_within_each_repetition(probe: Any) -> None:
    """A1 B1 A2 B2, then again: ranks outer, builds inner, repetitions outermost."""
    assert probe.combinations([Path("A"), Path("B")], [1, 2], 2) == [
        (0, 0, 1), (0, 1, 1), (0, 0, 2), (0, 1, 2), (1, 0, 1), (1, 1, 1), (1, 0, 2), (1, 1, 2)]


def test_schedule_runs_each_count_of_copies_in_turn(probe: Any) -> None:
    """--copies 1 2: per repetition all combinations alone, then all as two copies at once."""
    assert probe.schedule([Path("A"), Path("B")], [2], 2, [1, 2]) == [
        (0, 0, 2, 1), (0, 1, 2, 1), (0, 0, 2, 2), (0, 1, 2, 2),
        (1, 0, 2, 1), (1, 1, 2, 1), (1, 0, 2, 2), (1, 1, 2, 2)]
    assert probe.schedule([Path("A")], [1, 2], 1, [1]) == [
        (k, b, r, 1) for k, b, r in probe.combinations([Path("A")], [1, 2], 1)]


def test_summary_gives_the_gain_of_copies_side_by_side(probe: Any) -> None:
    """Loop times 20 and 22 s alone, 30 and 26 s (two probes each) as two copies at once: medians
    21 and 28 s, so the two together do 2 x 21 / 28 = 1.50 times the work of one alone."""
    def row(n: int, loop: float) -> dict[str, Any]:
        return {"friction": 0.5, "friction_stick": None, "build_index": 0, "build": "/b0", "ranks": 2,
                "fiberdem": "sha256:" + "0" * 64, "exit": 0, "loop_s": loop, "cpu_s": loop, "final_state": "s",
                "copies": n}
    lines = probe.summary([row(1, 20.0), row(2, 30.0), row(2, 30.0), row(1, 22.0), row(2, 26.0), row(2, 26.0)])
    assert "on 2 rank(s): loop 21.00 [20.00-22.00] s" in lines[1], lines
    assert "on 2 rank(s), 2 copies at once: loop 28.00 [26.00-30.00] s" in lines[2], lines
    assert lines[3] == "    2 copies together: 1.50 x the throughput of one alone", lines
    assert lines[-1].startswith("  final states: identical (1 distinct of 6"), lines


def test_summary_flags_different_final_states(probe: Any) -> None:
    def row(b: int, loop: float, cpu: float, state: str) -> dict[str, Any]:
        return {"friction": 0.5, "friction_stick": None, "build_index": b, "build": f"/b{b}",
                "ranks": 2, "fiberdem": "sha256:" + "0" * 64, "exit": 0, "loop_s": loop, "cpu_s": cpu,
                "final_state": state}
    same = probe.summary([row(0, 20.0, 40.0, "s"), row(1, 18.0, 20.0, "s"), row(0, 17.0, 34.0, "s"),
                          row(1, 17.5, 19.0, "s"), row(0, 16.0, 33.0, "s"), row(1, 20.0, 22.0, "s")])
    assert same[0] == "setting friction 0.5"
    assert "loop 17.00 [16.00-20.00] s, CPU 34.00 [33.00-40.00] s over 3 run(s)" in same[1], same
    assert "loop 18.00 [17.50-20.00] s, CPU 20.00 [19.00-22.00] s over 3 run(s)" in same[2], same
    assert same[-1].startswith("  final states: identical"), same
    differ = probe.summary([row(0, 20.0, 40.0, "s"), row(1, 18.0, 20.0, "t")])
    assert differ[-1].startswith("  final states: DIFFERENT (2 distinct of 2"), differ
    missing = probe.summary([row(0, 20.0, 40.0, "s"), {**row(1, 18.0, 20.0, "s"), "final_state": None}])
    assert "DIFFERENT" in missing[-1], missing


@pytest.mark.parametrize(("args", "option", "allowed"), [
    (["--ranks", "0"], "--ranks", f"1..{os.cpu_count() or 1}"),
    (["--ranks", str((os.cpu_count() or 1) + 1)], "--ranks", f"1..{os.cpu_count() or 1}"),
    (["--repeat", "0"], "--repeat", "1..100"),
    (["--repeat", "101"], "--repeat", "1..100"),
    (["--builds", "BUILD", "NOWHERE"], "--builds", "bin/fiberdem not found"),
    (["--builds", "BUILD", "--concurrency", "10"], "--concurrency", "1e5..1e10"),
    (["--builds", "BUILD", "BUILD", "--parallel", "2"], "--parallel", "one build"),
    (["--builds", "BUILD", "--repeat", "2", "--parallel", "2"], "--parallel", "--repeat 1"),
    (["--builds", "BUILD", "--copies", "1", "2", "--parallel", "2"], "--parallel", "no --copies"),
    (["--builds", "BUILD", "--copies", "0"], "--copies", f"1..{os.cpu_count() or 1}"),
    (["--builds", "BUILD", "--copies", "1", "1"], "--copies", "each N once"),
])
def test_bad_arguments_exit_2_before_anything_runs(run: Path, args: list[str], option: str,
                                                   allowed: str) -> None:
    """Exit status 2 naming the option and the allowed values; no probe folder, no results file
    (BUILD holds a fiberdem that is not a program: a probe that ran would fail otherwise)."""
    fake = run / "fake-build"
    (fake / "bin").mkdir(parents=True)
    (fake / "bin" / "fiberdem").write_text("")
    args = [str(fake) if a == "BUILD" else str(run / "nowhere") if a == "NOWHERE" else a for a in args]
    proc = run_script("--run", str(run), "--step", "4000", "--settings", "0.5:", "--probes",
                      str(run / "probes"), "--out", str(run / "out.json"), *args)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert option in proc.stderr and allowed in proc.stderr, proc.stderr
    assert not (run / "probes").exists() and not (run / "out.json").exists()


@pytest.fixture(scope="module")
def laydown_run(tmp_path_factory: pytest.TempPathFactory, fiberdem_build: Path,
                fiberform_cmd: list[str]) -> Path:
    """A lay-down run folder of the tiny scene (scene.yaml, laydown/work with restart files)."""
    work = tmp_path_factory.mktemp("probe-builds")
    (work / "tiny.yaml").write_text(TINY)
    proc = subprocess.run([*fiberform_cmd, "run", "tiny.yaml", "--build-dir", str(fiberdem_build)],
                          cwd=work, capture_output=True, text=True, errors="replace", timeout=900)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    run = work / "runs" / "a"
    assert (run / "laydown" / "work" / "laydown.1000.restart").is_file()
    (run / "scene.yaml").write_text(TINY)
    return run


@pytest.mark.system
def test_two_builds_one_and_two_ranks_end_in_the_same_state(laydown_run: Path, fiberdem_build: Path,
                                                            tmp_path: Path) -> None:
    """The build and a copy of it (bin/fiberdem a symlink, a REVISION file) on 1 and 2 ranks, twice:
    the rows come in the alternating order, each with the build, its fiberdem's hash, the ranks,
    loop and CPU time, and the same final-state hash (the lay-down does not depend on the
    decomposition); the machine's throughput before and after is recorded."""
    if (os.cpu_count() or 1) < 2:
        pytest.skip("needs 2 cores")
    copy = tmp_path / "build-copy"
    (copy / "bin").mkdir(parents=True)
    (copy / "bin" / "fiberdem").symlink_to(fiberdem_build / "bin" / "fiberdem")
    (copy / "REVISION").write_text("69802b8-dirty\n")
    out = tmp_path / "probe.json"
    proc = run_script("--run", str(laydown_run), "--step", "1000", "--steps", "100", "--chunk", "50",
                      "--settings", "0.5:", "--builds", str(fiberdem_build), str(copy), "--ranks", "1", "2",
                      "--repeat", "2", "--concurrency", "1e5", "--probes", str(tmp_path / "probes"),
                      "--out", str(out))
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    rows = json.loads(out.read_text())["rows"]
    assert [(r["repetition"], r["build_index"], r["ranks"]) for r in rows] == [
        (k, b, r) for k in range(2) for r in (1, 2) for b in range(2)]
    for r in rows:
        assert r["exit"] == 0 and r["simulated_steps"] == 100, r
        assert r["build"] == str(fiberdem_build if r["build_index"] == 0 else copy), r
        assert r["loop_s"] > 0.0 and r["cpu_s"] >= r["cpu_user_s"] > 0.0, r
        assert 0.0 < r["throughput_cores_before"] <= 2.5 and 0.0 < r["throughput_cores_after"] <= 2.5, r
        assert r["folder"].endswith(f"-b{r['build_index']}-np{r['ranks']}"), r
        assert r["launch"] == ("mpirun --bind-to none -np 2" if r["ranks"] == 2 else ""), r
    assert rows[1]["build_revision"] == "69802b8-dirty"
    assert rows[0]["build_revision"] == build_revision(fiberdem_build)
    assert len({r["fiberdem"] for r in rows}) == 1
    states = {r["final_state"] for r in rows}
    assert len(states) == 1 and states.pop().startswith("sha256:"), rows
    # the dump: every node, sorted by id, position and velocity at full precision
    dump = (Path(rows[-1]["folder"]) / "final.dump").read_text().splitlines()
    assert dump[1] == "1100" and dump[8].split() == ["ITEM:", "ATOMS", "id", "x", "y", "z", "vx", "vy", "vz"]
    atoms = [line.split() for line in dump[9:]]
    assert len(atoms) == int(dump[3]) == rows[-1]["nodes"] > 0
    assert [int(a[0]) for a in atoms] == sorted(int(a[0]) for a in atoms)
    assert all(len(a) == 7 for a in atoms) and any(float(a[6]) != 0.0 for a in atoms)
    assert max(len(a[3].lstrip("-").replace(".", "").lstrip("0").split("e")[0]) for a in atoms) >= 16
    summary = proc.stdout[proc.stdout.index("setting friction 0.5\n"):]
    assert summary.count(" over 2 run(s)") == 4, summary
    assert "final states: identical (1 distinct of 8 probe(s))" in summary, summary


@pytest.mark.system
def test_copies_side_by_side_end_in_the_same_state(laydown_run: Path, fiberdem_build: Path, tmp_path: Path) -> None:
    """--copies 1 2 on one rank: one probe alone, then two at the same time, each in its own
    folder (-c0, -c1); every row records its count and copy, all three end in the same state, and
    the table gives the gain of the two copies together."""
    if (os.cpu_count() or 1) < 2:
        pytest.skip("needs 2 cores")
    out = tmp_path / "probe.json"
    proc = run_script("--run", str(laydown_run), "--step", "1000", "--steps", "100", "--chunk", "50",
                      "--settings", "0.5:", "--builds", str(fiberdem_build), "--copies", "1", "2",
                      "--probes", str(tmp_path / "probes"), "--out", str(out))
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    rows = json.loads(out.read_text())["rows"]
    assert sorted((r["copies"], r["copy"]) for r in rows) == [(1, 0), (2, 0), (2, 1)], rows
    for r in rows:
        assert r["exit"] == 0 and r["simulated_steps"] == 100 and r["loop_s"] > 0.0, r
        assert r["folder"].endswith(f"-c{r['copy']}"), r
    assert len({r["folder"] for r in rows if r["copies"] == 2}) == 2
    states = {r["final_state"] for r in rows}
    assert len(states) == 1 and states.pop().startswith("sha256:"), rows
    assert "2 copies together: " in proc.stdout and "final states: identical (1 distinct of 3" in proc.stdout, \
        proc.stdout[-2000:]
