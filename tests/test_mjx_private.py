"""MJX's private modules are read through one door, which knows the MJX releases it was checked against."""

from __future__ import annotations

import importlib.metadata
import importlib.util
import os
import re
from pathlib import Path

import pytest
from helpers import ENV, cli

from mjx_pusht.model import mjx_private

PACKAGE = Path(mjx_private.__file__).resolve().parents[1]


def test_no_module_but_the_door_imports_mjx_internals():
    """Every `mujoco.mjx.third_party`, `mujoco.mjx._src` or `mujoco.mjx.warp` reference in the package is in
    mjx_private.py: a new one elsewhere would escape the version check."""
    private = re.compile(r"mujoco\.mjx\.(third_party|_src|warp)\b|from mujoco\.mjx import (_src|warp|third_party)")
    found = [f"{p.relative_to(PACKAGE)}:{n}" for p in PACKAGE.rglob("*.py") if p.name != "mjx_private.py"
             for n, line in enumerate(p.read_text().splitlines(), 1) if private.search(line)]
    assert found == []


def test_the_installed_mjx_is_known_and_each_door_opens_on_what_the_package_reads():
    version = importlib.metadata.version("mujoco-mjx")
    assert mjx_private.check() == version
    assert version.rsplit(".", 1)[0] in mjx_private.KNOWN_MJX
    mjw = mjx_private.mujoco_warp()
    assert callable(mjw.put_model) and callable(mjw.put_data) and callable(mjw.step)
    wd, wprim, wtypes = mjx_private.warp_collision()
    key = (wtypes.GeomType.BOX, wtypes.GeomType.BOX)
    assert key in wd.MJ_COLLISION_TABLE and isinstance(wprim._PRIMITIVE_COLLISIONS, dict)
    jd, jtypes = mjx_private.jax_collision()
    assert (jtypes.GeomType.PLANE, jtypes.GeomType.BOX) in jd._COLLISION_FUNC
    assert callable(mjx_private.render_context().get)
    assert importlib.util.find_spec(mjx_private.FFI_MODULE) is not None


@pytest.mark.parametrize("installed, says", [
    ({"mujoco-mjx": "3.18.0"}, "mujoco-mjx 3.18.0 is installed, but mjx_pusht reads MJX's private modules"),
    ({"mujoco-mjx": "4.0.0"}, "knows them only in mujoco-mjx 3.17.x"),
    ({"mujoco-mjx": None}, "MJX is not installed"),
    ({"mujoco": "3.17.0", "mujoco-core": "4.0.0"}, "mujoco 3.17.0 is installed over mujoco-core 4.0.0"),
])
def test_an_unknown_mjx_or_a_mujoco_3_over_mujoco_4s_core_is_refused_in_one_line(monkeypatch, installed, says):
    real = mjx_private._installed
    monkeypatch.setattr(mjx_private, "_installed", lambda dist: installed[dist] if dist in installed else real(dist))
    with pytest.raises(mjx_private.MjxVersionError, match=re.escape(says)) as e:
        mjx_private.warp_collision()
    assert "\n" not in str(e.value)


def test_mujoco_4_with_its_own_core_passes(monkeypatch):
    """MuJoCo 4 is a meta-package over mujoco-core of the same version: that pair is whole, not a leftover."""
    versions = {"mujoco": "4.0.0", "mujoco-core": "4.0.0", "mujoco-mjx": "3.17.0"}
    monkeypatch.setattr(mjx_private, "_installed", versions.get)
    assert mjx_private.check() == "3.17.0"


def test_the_cli_refuses_an_mjx_it_does_not_know_in_one_line(tmp_path):
    """`tree --colliders` reads MJX's collision tables: with a mujoco-mjx 9.0.0 found first on the path, as pip
    would leave it, the command says so in one line and exits non-zero."""
    dist = tmp_path / "mujoco_mjx-9.0.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: mujoco-mjx\nVersion: 9.0.0\n")
    env = {**ENV, "PYTHONPATH": os.pathsep.join(filter(None, [str(tmp_path), ENV.get("PYTHONPATH")]))}
    r = cli("tree", "--colliders", env=env)
    assert r.returncode != 0
    assert r.stderr.strip().splitlines() == [r.stderr.strip()] and "mujoco-mjx 9.0.0 is installed" in r.stderr
    assert "Traceback" not in r.stderr
