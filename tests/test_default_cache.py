"""``import softplan_jax`` turns jax's persistent compilation cache on (a script's second run loads
the planner's programs from disk), with a documented way out, and never over the user's own
settings. Each case in a fresh process (the import is what is tested)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from session import REPO, subprocess_env

PROBE = """
import json, os, sys
import jax
if os.environ.get("PROBE_SET_DIR"):
    jax.config.update("jax_compilation_cache_dir", os.environ["PROBE_SET_DIR"])
import softplan_jax as sp
out = {"dir": jax.config.jax_compilation_cache_dir}
if os.environ.get("PROBE_COMPILE"):
    jax.jit(lambda x: x * 2 + 1)(jax.numpy.ones(3)).block_until_ready()
    d = out["dir"]
    out["files"] = sum(len(f) for _, _, f in os.walk(d)) if d else 0
    out["disabled"] = [sp.disable_compilation_cache(), sp.disable_compilation_cache()]
    out["after"] = jax.config.jax_compilation_cache_dir
print(json.dumps(out))
"""


def _probe(tmp_path, **env_updates):
    env = subprocess_env()
    for k in ("JAX_COMPILATION_CACHE_DIR", "SOFTPLAN_CACHE_DIR", "SOFTPLAN_COMPILATION_CACHE", "SOFTPLAN_JAX_NO_CACHE",
              "JAX_ENABLE_COMPILATION_CACHE"):
        env.pop(k, None)
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    env.update(env_updates)
    p = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, env=env, cwd=REPO, timeout=120)
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


def test_import_turns_the_cache_on_and_it_keeps_programs(tmp_path):
    out = _probe(tmp_path, PROBE_COMPILE="1", JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0")
    assert out["dir"] == os.path.join(str(tmp_path / "xdg"), "softplan_jax", "jax")
    assert out["files"] >= 1  # the compiled program is on disk
    assert out["disabled"] == [True, False] and out["after"] is None  # turned off after the import too


def test_the_opt_out_and_the_users_own_settings(tmp_path):
    assert _probe(tmp_path, SOFTPLAN_JAX_NO_CACHE="1")["dir"] is None
    assert _probe(tmp_path, SOFTPLAN_COMPILATION_CACHE="0")["dir"] is None
    assert _probe(tmp_path, JAX_ENABLE_COMPILATION_CACHE="false")["dir"] is None  # jax's own switch: not overridden
    mine = str(tmp_path / "mine")
    assert _probe(tmp_path, JAX_COMPILATION_CACHE_DIR=mine)["dir"] == mine
    assert _probe(tmp_path, PROBE_SET_DIR=mine)["dir"] == mine
