"""The user-facing persistent compilation cache (softplan_jax.compilation_cache)."""

import os
import subprocess
import sys

from session import REPO, subprocess_env

from softplan_jax.compilation_cache import compilation_cache_dir


def test_directory_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv("SOFTPLAN_COMPILATION_CACHE", raising=False)
    monkeypatch.setenv("SOFTPLAN_CACHE_DIR", str(tmp_path / "c"))
    assert compilation_cache_dir() == os.path.join(str(tmp_path / "c"), "jax")
    monkeypatch.delenv("SOFTPLAN_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert compilation_cache_dir() == os.path.join(str(tmp_path / "xdg"), "softplan_jax", "jax")
    for off in ("0", "off", "false"):
        monkeypatch.setenv("SOFTPLAN_COMPILATION_CACHE", off)
        assert compilation_cache_dir() is None


def _enable_in_fresh_process(env_updates, drop=()):
    env = subprocess_env()
    for k in ("JAX_COMPILATION_CACHE_DIR", "SOFTPLAN_CACHE_DIR", "SOFTPLAN_COMPILATION_CACHE", *drop):
        env.pop(k, None)
    env.update(env_updates)
    code = ("import jax, softplan_jax as sp; d = sp.enable_compilation_cache(); "
            "print(d); print(jax.config.jax_compilation_cache_dir)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=REPO,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.split()


def test_enable_sets_the_user_cache_and_respects_opt_out_and_user_settings(tmp_path):
    d, cfg = _enable_in_fresh_process({"XDG_CACHE_HOME": str(tmp_path)})
    assert d == cfg == os.path.join(str(tmp_path), "softplan_jax", "jax") and os.path.isdir(d)
    d, cfg = _enable_in_fresh_process({"XDG_CACHE_HOME": str(tmp_path), "SOFTPLAN_COMPILATION_CACHE": "0"})
    assert d == "None" and cfg == "None"
    mine = str(tmp_path / "mine")
    d, cfg = _enable_in_fresh_process({"JAX_COMPILATION_CACHE_DIR": mine, "XDG_CACHE_HOME": str(tmp_path)})
    assert d == cfg == mine
