# SPDX-License-Identifier: GPL-3.0-or-later
"""The stage graph (fiberform.pipeline; issue 14): order from the stages' declared needs and
products, --from/--to/--force selection, and ``fiberform status`` on real stage runs (fabric and
flow: Python and OpenFOAM), including a running stage, an interrupted one and a killed one."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Mapping
from pathlib import Path

import h5py
import pytest

from cli_helpers import parse_status, processes_under
from fiberform.errors import ConfigError
from fiberform.pipeline import StageGraph, applicable_stages
from fiberform.scene import Scene, load_scene
from fiberform.stages import STAGES, Stage, StageContext

ROOT = Path(__file__).resolve().parents[1]


def _ctx(scene_path: Path) -> StageContext:
    return StageContext(scene=load_scene(scene_path), scene_path=scene_path, build_dir=ROOT / "build")


@pytest.fixture(scope="module")
def demo() -> StageGraph:
    ctx = _ctx(ROOT / "scenes" / "demo.yaml")
    return StageGraph(applicable_stages(ctx.scene), ctx)


def test_demo_order_follows_the_declared_needs(demo: StageGraph) -> None:
    assert demo.order == ["generate", "fabric", "flow", "laydown", "press", "permeability",
                          "permeability-press"]
    assert set(demo.upstream["laydown"]) == {"generate", "fabric", "flow"}
    assert set(demo.upstream["press"]) == {"laydown", "generate", "fabric"}
    assert set(demo.upstream["permeability-press"]) == {"press", "generate", "fabric"}
    # every file a demo stage reads is made by a stage of the demo (a wrong path in needs() fails)
    assert all(not ext for ext in demo.external.values()), demo.external
    for name, ups in demo.upstream.items():
        assert all(demo.order.index(u) < demo.order.index(name) for u in ups)


def test_needs_are_products_of_the_registered_stages(demo: StageGraph) -> None:
    ctx = demo.ctx
    made = {p for s in STAGES.values() for p in s.product_paths(ctx)}
    for s in demo.stages.values():
        for key, p in s.needs(ctx).items():
            assert p in made, f"{s.name} needs {key} = {p}, which no stage makes"


def test_from_and_to_select_downstream_and_upstream(demo: StageGraph) -> None:
    names = lambda stages: [s.name for s in stages]  # noqa: E731
    assert names(demo.select()) == demo.order
    assert names(demo.select("laydown")) == ["laydown", "press", "permeability", "permeability-press"]
    assert names(demo.select(None, "laydown")) == ["generate", "fabric", "flow", "laydown"]
    assert names(demo.select("flow", "laydown")) == ["flow", "laydown"]
    assert names(demo.select("fabric", "permeability")) == ["fabric", "flow", "laydown", "permeability"]
    with pytest.raises(ConfigError, match="does not depend"):
        demo.select("press", "flow")
    with pytest.raises(ConfigError, match="--from 'lay-down': not a stage"):
        demo.select("lay-down")


def test_from_with_missing_upstream_products_exits_2(tmp_path: Path) -> None:
    shutil.copy(ROOT / "scenes" / "demo.yaml", tmp_path / "demo.yaml")
    r = subprocess.run([sys.executable, "-m", "fiberform", "run", "demo.yaml", "--from", "laydown"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 2, r.stderr
    assert "--from laydown: laydown needs runs/demo/fibers/fibers.h5 (fibers_h5) from stage generate" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo.yaml"]


class _Fake(Stage):
    summary, requires, uses, code_version = "fake", (), (), 1

    def __init__(self, name: str, makes: str, reads: str) -> None:
        self.name, self.folder, self.products = name, name, (makes,)  # type: ignore[misc]
        self._reads = reads

    def needs(self, ctx: StageContext) -> dict[str, Path]:
        return {"x": ctx.scene.output_path / self._reads}

    def produce(self, ctx: StageContext, h5: h5py.File, tmp: Mapping[str, Path],
                hashes: Mapping[str, str]) -> None:
        raise AssertionError("never run")


def test_a_cycle_is_refused() -> None:
    ctx = StageContext(scene=Scene.model_validate({"name": "c", "run": {"timestep_s": 1e-6, "duration_s": 1e-5}}),
                       scene_path=Path("c.yaml"), build_dir=Path("build"))
    a, b = _Fake("a", "a.h5", "b/b.h5"), _Fake("b", "b.h5", "a/a.h5")
    with pytest.raises(ConfigError, match="cycle among: a, b"):
        StageGraph([a, b], ctx)
    c = _Fake("c", "c.h5", "a/a.h5")
    # c needs a, which needs an unknown file: order a, c; the unknown file is external
    g = StageGraph([c, _Fake("a", "a.h5", "elsewhere/z.h5")], ctx)
    assert g.order == ["a", "c"] and g.external["a"] == (ctx.scene.output_path / "elsewhere/z.h5",)


# ---- fiberform status / run on real stages ----------------------------------------------------

SCENE = """name: pipe
run: {timestep_s: 1.0e-6, duration_s: 1.0e-3}
fabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3, voxel_size_m: 10.0e-6}
flow: {cell_size_m: 50.0e-6, delta_p_Pa: 100.0}
"""
ENV = dict(os.environ, WM_PROJECT_DIR=os.environ.get("WM_PROJECT_DIR", "/usr/share/openfoam"))


def _ff(d: Path, *args: str, timeout: float = 900) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "fiberform", *args], cwd=d, env=ENV, capture_output=True,
                          text=True, errors="replace", timeout=timeout, check=False)


def _status(d: Path) -> dict[str, tuple[str, str]]:
    r = _ff(d, "status", "s.yaml", timeout=120)
    assert r.returncode == 0, r.stderr
    return parse_status(r.stdout)


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start_flow(d: Path) -> subprocess.Popen[str]:
    """`fiberform flow` in its own session; returns once its status says running."""
    # SIGINT at its default, so that Python installs its Ctrl-C handler in fiberform even when this
    # test runs in a shell's background job (a non-interactive shell starts those with SIGINT
    # ignored, and an ignored signal stays ignored across exec: fiberform then never sees the SIGINT)
    proc = subprocess.Popen([sys.executable, "-m", "fiberform", "flow", "s.yaml", "--force"], cwd=d, env=ENV,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=_default_sigint)
    state = d / "runs/pipe/flow/stage-state.json"
    deadline = time.monotonic() + 120
    while not (state.is_file() and '"running"' in state.read_text()):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "flow never started"
        time.sleep(0.05)
    assert _status(d)["flow"][0] == "running"
    return proc


@pytest.mark.system
@pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM (simpleFoam) not installed")
def test_status_through_run_change_interrupt_and_kill(tmp_path: Path) -> None:
    d = tmp_path
    (d / "s.yaml").write_text(SCENE)
    assert _status(d) == {"fabric": ("missing", ""), "flow": ("missing", "")}

    # --to fabric runs fabric only; flow stays missing
    r = _ff(d, "run", "s.yaml", "--to", "fabric")
    assert r.returncode == 0, r.stderr
    assert "[1/1] fabric" in r.stdout and "flow" not in r.stdout
    st = _status(d)
    assert st["fabric"][0] == "done" and st["flow"] == ("missing", "")

    # the interruptions below hit a flow that cannot finish first (a residual tolerance it never
    # reaches within 100000 iterations; the default one finishes in ~10 s, and on a loaded machine
    # it once did so between the status check and the signal: exit 0); the scene's flow is put
    # back before the flow is run to the end
    (d / "s.yaml").write_text(SCENE.replace("delta_p_Pa: 100.0}", "delta_p_Pa: 100.0, "
                                            "residual_tolerance: 1.0e-300, max_iterations: 100000}"))
    # a running flow, interrupted (SIGINT): failed, "interrupted", no products
    proc = _start_flow(d)
    os.killpg(proc.pid, signal.SIGINT)
    proc.wait(timeout=120)
    state, detail = _status(d)["flow"]
    assert proc.returncode == 130 and state == "failed" and "interrupted" in detail, (proc.returncode, detail)
    assert not (d / "runs/pipe/flow/flow.h5").exists()

    # SIGTERM to fiberform alone (a batch system's time limit): it stops its OpenFOAM children
    # (they run in a session of their own), records failed, exits 143
    proc = _start_flow(d)
    time.sleep(1.0)  # into the OpenFOAM tools
    os.kill(proc.pid, signal.SIGTERM)
    proc.wait(timeout=120)
    state, detail = _status(d)["flow"]
    assert proc.returncode == 143 and state == "failed" and "SIGTERM" in detail, (proc.returncode, detail)
    assert processes_under(d) == [], processes_under(d)

    # killed outright (SIGKILL, no chance to clean up): failed, the process is gone
    proc = _start_flow(d)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=60)
    state, detail = _status(d)["flow"]
    assert state == "failed" and "is gone" in detail, detail

    # --from flow reruns flow only (fabric is up to date and not selected) -> done
    (d / "s.yaml").write_text(SCENE)
    r = _ff(d, "run", "s.yaml", "--from", "flow")
    assert r.returncode == 0, r.stderr
    assert "[1/1] flow" in r.stdout
    st = _status(d)
    assert st["flow"][0] == "done" and not (d / "runs/pipe/flow/stage-state.json").exists()

    # a changed fabric field: fabric stale (its scene hash), and so is flow (it reads the fabric)
    (d / "s.yaml").write_text(SCENE.replace("voxel_size_m: 10.0e-6", "voxel_size_m: 12.5e-6"))
    st = _status(d)
    assert st["fabric"][0] == "stale" and "scene" in st["fabric"][1], st
    assert st["flow"][0] == "stale", st

    # --force names a stage outside the selection: exit 2, nothing run
    r = _ff(d, "run", "s.yaml", "--to", "fabric", "--force", "flow")
    assert r.returncode == 2 and "--force 'flow'" in r.stderr, r.stderr
    r = _ff(d, "run", "s.yaml", "--from", "nosuch")
    assert r.returncode == 2 and "--from 'nosuch': not a stage" in r.stderr, r.stderr


@pytest.mark.parametrize("args, words", [
    (["run", "demo.yaml", "--from", "lay-down"], "--from 'lay-down': not a stage"),
    (["run", "demo.yaml", "--to", "pressing"], "--to 'pressing': not a stage"),
    (["run", "demo.yaml", "--from", "press", "--to", "flow"], "does not depend"),
    (["run", "demo.yaml", "--from", "permeability", "--to", "press"], "does not depend"),
    (["run", "demo.yaml", "--force", "nosuch"], "--force 'nosuch': not a stage"),
    (["run", "demo.yaml", "--to", "flow", "--force", "laydown"], "--force 'laydown': not among"),
    (["run", "demo.yaml", "--from", "press"], "press needs"),
    (["run", "demo.yaml", "--from", "demo-particles"], "--from 'demo-particles': not a stage of this scene"),
    (["status", "missing.yaml"], "file not found"),
    (["run", "missing.yaml"], "file not found"),
])
def test_bad_run_commands_exit_2_and_write_nothing(tmp_path: Path, args: list[str], words: str) -> None:
    shutil.copy(ROOT / "scenes" / "demo.yaml", tmp_path / "demo.yaml")
    r = subprocess.run([sys.executable, "-m", "fiberform", *args], cwd=tmp_path, capture_output=True, text=True,
                       timeout=120, check=False)
    assert r.returncode == 2, r.stdout + r.stderr
    assert words in r.stderr, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo.yaml"]


@pytest.mark.system
def test_more_ranks_than_cores_exits_2_before_the_stage_writes_anything(tmp_path: Path) -> None:
    """A stage whose MPI ranks exceed the cores is refused (exit status 2, naming the remedy)
    before it creates its folder or removes products: the fabric before it finished, the flow
    stage left nothing behind."""
    cores = os.cpu_count() or 1
    (tmp_path / "s.yaml").write_text(SCENE.replace("delta_p_Pa: 100.0}", f"delta_p_Pa: 100.0, ranks: {cores + 1}}}"))
    r = _ff(tmp_path, "run", "s.yaml")
    assert r.returncode == 2 and f"{cores + 1} MPI ranks requested" in r.stderr and "--oversubscribe" in r.stderr, \
        r.stderr
    assert (tmp_path / "runs/pipe/fabric/fabric.h5").is_file()
    assert not (tmp_path / "runs/pipe/flow").exists()
