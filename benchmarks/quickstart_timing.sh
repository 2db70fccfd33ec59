#!/usr/bin/env bash
# Times the README's Python quick start in fresh processes:
#   run 1: an empty softplan_jax cache (the first run a user sees),
#   run 2: the same cache again (every later run),
#   run 3: the cache turned off (SOFTPLAN_JAX_NO_CACHE=1), for comparison.
# Usage: bash benchmarks/quickstart_timing.sh [PYTHON]   (default: python)
# Run on a quiet machine; each run prints its wall time in seconds.
set -euo pipefail
PY="${1:-python}"
WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT
cat > "$WORK/quickstart.py" <<'PYEOF'
import jax
jax.config.update("jax_enable_x64", True)   # float64; float32 works too
import jax.numpy as jnp
import softplan_jax as sp

# The arm: rows [L_i, theta_i, phi_i] (paper §2.1, R_i = Rz(phi) Ry(theta)).
q = jnp.array([[1.0, 0.3, 0.0], [1.0, 0.0, 2.1], [1.0, -0.4, 2.1]])
sp.tip_position(q)                           # (3,)
sp.point_jacobian(q, 2, 1.0)                 # (3, 9): d point / d q at segment 2, s = 1

# An obstacle: X = 1, Y = u, Z = 0.5 - u for u in [-2, 2] (paper Table 2).
line = sp.PolynomialCurve([[1.0, 0.0], [0.0, 1.0], [0.5, -1.0]], (-2.0, 2.0))
cp = sp.closest_point(q, line)               # .distance .segment .s .u .arm_point .obstacle_point
jax.grad(lambda q: sp.closest_point(q, line).distance)(q)   # exact gradient

# Plan (paper eq. 9), with the curve method or the N-point model.
scenario = sp.make_scenario(goal=[1.1, -0.8, 0.9], obstacles=[line])
result = sp.plan(scenario, method="curve", max_steps=300)
result.status, result.iterations, result.collided, result.min_clearance
result.q                                     # (iterations + 1, 3, 3) configurations
sp.plan(scenario, method="points", n_points=50)
sp.plan_fallback(sp.paper_scenario("tree"))  # local planner, then the global search if needed
print("cache:", jax.config.jax_compilation_cache_dir)
PYEOF
# No user cache settings leak in: the library's own default decides.
unset JAX_COMPILATION_CACHE_DIR SOFTPLAN_COMPILATION_CACHE SOFTPLAN_JAX_NO_CACHE SOFTPLAN_CACHE_DIR || true
export XDG_CACHE_HOME="$WORK/xdg"
run() {
  local label="$1"; shift
  local t0 t1
  t0=$(date +%s.%N)
  env "$@" "$PY" "$WORK/quickstart.py"
  t1=$(date +%s.%N)
  printf "%-28s %s s\n" "$label" "$("$PY" -c "print(f\"{$t1 - $t0:.1f}\")")"
}
run "run 1 (empty cache)" XDG_CACHE_HOME="$WORK/xdg"
run "run 2 (warm cache)" XDG_CACHE_HOME="$WORK/xdg"
run "run 3 (cache off)" XDG_CACHE_HOME="$WORK/xdg" SOFTPLAN_JAX_NO_CACHE=1
du -sh "$WORK/xdg/softplan_jax" 2>/dev/null || true
