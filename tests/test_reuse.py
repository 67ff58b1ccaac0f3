# SPDX-License-Identifier: GPL-3.0-or-later
"""fiberform.reuse.adopt_stages (issues 10 and 15): a sibling run's finished stage folders are
taken over only where the stage runner then skips them.

- without external programs (generate, fabric): the copied stages are skipped by the stage runner
  (nothing rewritten) and kept by a second call; a target of another seed gets the fabric but not
  the fibers (generate hashes the seed) and nothing is written for it; a donor without products
  or with a failed stage gives ``absent``; a running target stage is left alone (``busy``); a stage
  the scene lacks is a ConfigError; bench/laydown/run_thesis.py's donor_stages takes over through it;
- with the real lay-down (system, about 30 s): the campaign's pressure-press scene of a tiny point
  takes over generate, fabric, flow and the lay-down of the point's run, and the stage runner
  skips all four (the lay-down's products byte-identical: not laid down again); a scene differing
  in one lay-down field gets generate, fabric and flow but not the lay-down.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import yaml

from fiberform import campaign as cp
from fiberform.errors import ConfigError
from fiberform.pipeline import plan_run, run_pipeline
from fiberform.reuse import ADOPTED_NAME, adopt_stages
from fiberform.scene import parse_scene
from fiberform.stages import STAGES, StageContext

from bench_scripts import load_bench_script
from test_campaign import TINY_BASE, tiny_point

QUICK = [STAGES["generate"], STAGES["fabric"]]


def _ctx(data: dict[str, Any], build: Path) -> StageContext:
    return StageContext(scene=parse_scene(data, data["name"]), scene_path=Path(f"{data['name']}.yaml"), build_dir=build)


def _quick_scene(name: str, seed: int = 3) -> dict[str, Any]:
    """The tiny scene with its generate, fabric and flow stages (only the first two run here),
    output in runs/<name>."""
    d: dict[str, Any] = yaml.safe_load(TINY_BASE)
    for k in ("laydown", "contact", "permeability"):
        d.pop(k)
    d.update(name=name.replace("-", "_"), seed=seed, output_dir=f"runs/{name}")
    return d


def _actions(adopted: list[Any]) -> dict[str, str]:
    return {a.stage: a.action for a in adopted}


def test_copied_stages_are_skipped(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, build_dir: Path) -> None:
    monkeypatch.chdir(tmp_path)
    donor = _ctx(_quick_scene("donor"), build_dir)
    run_pipeline(donor, QUICK, set(), echo=lambda line: None)
    target = _ctx(_quick_scene("target"), build_dir)
    assert _actions(adopt_stages(target, Path("runs/donor"), ["fabric", "generate"])) == {
        "generate": "copied", "fabric": "copied"}
    lines: list[str] = []
    outcomes = run_pipeline(target, QUICK, set(), echo=lines.append)
    assert [o.skipped for o in outcomes] == [True, True], lines
    for f in ("fibers/fibers.h5", "fibers/fibers.nodes", "fabric/fabric.h5"):
        assert Path("runs/target", f).read_bytes() == Path("runs/donor", f).read_bytes()
    for stage, folder in (("generate", "fibers"), ("fabric", "fabric")):  # where each copy came from
        rec = json.loads(Path("runs/target", folder, ADOPTED_NAME).read_text())
        assert rec["stage"] == stage and rec["into_scene"] == "target.yaml"
        assert rec["adopted_from"] == str(Path("runs/donor", folder).resolve())
        assert rec["input_hashes"] == STAGES[stage].input_hashes(target)
    assert _actions(adopt_stages(target, Path("runs/donor"), ["generate", "fabric"])) == {
        "generate": "kept", "fabric": "kept"}
    # another seed: the fabric is the same, the fibers are not (nothing written for them)
    other = _ctx(_quick_scene("other", seed=4), build_dir)
    got = adopt_stages(other, Path("runs/donor"), ["generate", "fabric"])
    assert _actions(got) == {"generate": "differs", "fabric": "copied"}
    assert "scene" in got[0].detail and not Path("runs/other/fibers").exists()
    # a donor without products, or whose stage failed since: nothing to take over
    assert _actions(adopt_stages(_ctx(_quick_scene("t2"), build_dir), Path("runs/none"), ["generate"])) == {
        "generate": "absent"}
    (Path("runs/donor/fabric") / "stage-state.json").write_text(json.dumps({"state": "failed"}))
    assert _actions(adopt_stages(_ctx(_quick_scene("t3"), build_dir), Path("runs/donor"), ["fabric"])) == {
        "fabric": "absent"}
    # a target stage running is left alone
    busy = Path("runs/t4/fabric")
    busy.mkdir(parents=True)
    (busy / "stage-state.json").write_text(json.dumps({"state": "running", "pid": 1}))
    (Path("runs/donor/fabric") / "stage-state.json").unlink()
    assert _actions(adopt_stages(_ctx(_quick_scene("t4"), build_dir), Path("runs/donor"), ["fabric"])) == {
        "fabric": "busy"}
    assert sorted(p.name for p in busy.iterdir()) == ["stage-state.json"]
    with pytest.raises(ConfigError, match="'laydown'"):
        adopt_stages(target, Path("runs/donor"), ["laydown"])


def test_run_thesis_donor_stages(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, build_dir: Path) -> None:
    """bench/laydown/run_thesis.py takes over another variant's stages through adopt_stages, from
    any working directory (its scenes' output folders are relative to the repository root)."""
    bench = load_bench_script("bench/laydown/run_thesis.py", "run_thesis_reuse")
    runs = tmp_path / "root" / "runs"
    runs.mkdir(parents=True)
    monkeypatch.chdir(tmp_path / "root")
    run_pipeline(_ctx(_quick_scene("X-a-s3"), build_dir), QUICK, set(), echo=lambda line: None)
    target = runs / "X-b-s3"
    target.mkdir()
    (target / "scene.yaml").write_text(yaml.safe_dump(_quick_scene("X-b-s3")))
    monkeypatch.chdir(tmp_path)  # not the runs' working directory
    bench.donor_stages(runs, "X", 3, target, build_dir)
    assert (target / "fibers" / "fibers.h5").read_bytes() == (runs / "X-a-s3" / "fibers" / "fibers.h5").read_bytes()
    assert (target / "fabric" / "fabric.h5").is_file() and not (target / "flow").exists()  # the donor has no flow


@pytest.mark.system
def test_pressure_press_takes_over_the_laydown(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                build_dir: Path) -> None:
    if not (build_dir / "bin" / "fiberdem").is_file():
        pytest.fail(f"fiberdem not built in {build_dir}")
    monkeypatch.chdir(tmp_path)
    c, point = tiny_point(tmp_path)
    assert c.pressure_press is not None
    donor = _ctx(point, build_dir)
    run_pipeline(donor, plan_run(donor, None, "laydown")[0], set(), echo=lambda line: None)
    pressure = cp.pressure_scene(c, point)
    target = _ctx(pressure, build_dir)
    upstream = ("generate", "fabric", "flow", "laydown")
    got = adopt_stages(target, donor.scene.output_path, upstream)
    assert _actions(got) == dict.fromkeys(upstream, "copied"), got
    lines: list[str] = []
    outcomes = run_pipeline(target, plan_run(target, None, "laydown")[0], set(), echo=lines.append)
    assert [(o.stage, o.skipped) for o in outcomes] == [(n, True) for n in upstream], lines
    for f in ("laydown/laydown.h5", "laydown/sheet.restart"):
        assert (target.scene.output_path / f).read_bytes() == (donor.scene.output_path / f).read_bytes()
    # one lay-down field changed: the lay-down is not taken over (it would have to run)
    changed = {**pressure, "name": "changed", "output_dir": "runs/changed",
               "laydown": {**pressure["laydown"], "max_time_s": 0.005}}
    got = adopt_stages(_ctx(changed, build_dir), donor.scene.output_path, upstream)
    assert _actions(got) == {"generate": "copied", "fabric": "copied", "flow": "copied", "laydown": "differs"}
    assert "scene" in got[-1].detail and not Path("runs/changed/laydown").exists()
