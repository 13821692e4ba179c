"""A missing optional dependency is one line naming the extra that brings it (pip install 'mjx-pusht[EXTRA]'), in
the CLI and the Python API, before any work: nothing is written. Modules are hidden as a user without the extra
would meet them: `sys.modules[name] = None` makes `import name` fail as a missing package does."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from mjx_pusht.cli.commands import main
from mjx_pusht.errors import EXTRAS, MissingExtra, needs


@pytest.mark.parametrize("hidden, argv, extra", [
    ("optax", ["train", "--minutes", "1"], "train"),
    ("flax", ["train", "--algo", "ppo", "--backend", "mjx-jax"], "train"),
    ("brax", ["train", "--algo", "ppo", "--backend", "mjx-jax"], "train"),
    ("imageio", ["eval", "--seeds", "1", "--backend", "cpu", "--max-steps", "2", "--no-rerun", "--video", "v.mp4"],
     "video"),
    ("flax", ["eval", "--seeds", "1", "--backend", "cpu", "--max-steps", "2", "--no-rerun", "--controller",
              "policy:p.msgpack"], "train"),
])
def test_a_command_without_its_extra_is_one_line_naming_it_and_writes_nothing(hidden, argv, extra, tmp_path,
                                                                              monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, hidden, None)
    monkeypatch.chdir(tmp_path)
    assert main([*argv, "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"needs {hidden}" in err and f"pip install 'mjx-pusht[{extra}]'" in err, err
    assert not (tmp_path / "out").exists()


def test_the_api_says_the_same():
    from mjx_pusht.task.controllers import load
    from mjx_pusht.train.run import train_dagger

    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(sys.modules, "optax", None)
        with pytest.raises(MissingExtra, match=r"train_dagger needs optax.*mjx-pusht\[train\]"):
            train_dagger(None, "cpu", "nowhere")
        mp.setitem(sys.modules, "flax", None)
        with pytest.raises(MissingExtra, match=r"policy:PATH needs flax.*mjx-pusht\[train\]"):
            load("policy:p.msgpack")
    for extra, modules in EXTRAS.items():  # every extra's modules, named where they are missing
        for name in modules:
            with pytest.MonkeyPatch.context() as mp:
                mp.setitem(sys.modules, name, None)
                with pytest.raises(MissingExtra, match=rf"needs {name}, which is not installed: pip install "
                                                       rf"'mjx-pusht\[{extra}\]'"):
                    needs("this", extra)


def test_a_missing_module_no_extra_brings_keeps_its_traceback():
    from mjx_pusht.errors import requires

    with pytest.raises(ModuleNotFoundError):
        with requires("this", "train"):
            import mjx_pusht_no_such_module  # noqa: F401


def test_importing_an_env_module_without_its_extra_is_one_line():
    """gymnasium and brax hidden from a fresh interpreter (the env modules import them at the top)."""
    code = textwrap.dedent("""
        import sys
        sys.modules[sys.argv[1]] = None
        try:
            __import__(sys.argv[2])
        except ImportError as e:
            print(type(e).__name__, e)
    """)
    for hidden, module, extra in (("gymnasium", "mjx_pusht.envs.gym_pusht", "gym"),
                                  ("gymnasium", "mjx_pusht.envs.gym", "gym"), ("brax", "mjx_pusht.envs.brax", "brax")):
        out = subprocess.run([sys.executable, "-c", code, hidden, module], capture_output=True, text=True, timeout=120)
        assert out.stdout.strip().startswith("MissingExtra") and f"mjx-pusht[{extra}]" in out.stdout, out
