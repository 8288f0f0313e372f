#!/usr/bin/env bash
# Known truth on recordings, in one engine: the iiwa episodes that the
# fixtures' writer simulated with known parameters
# (third_party/fixtures/joint-recordings, truth.json) are imported, and
# `tune --recordings` fits damping, armature, dry friction and the delay
# with the PD gains known (episodes 1-2 fitted, 3-4 held out), as
# crates/cli/tests/tune_recordings.rs does for MuJoCo and mujoco4. The
# table then says whether each fitted value's interval covers the truth,
# as written and less the step's shift of an implicit servo (armature less
# dt kv; damping less dt kp too: see docs/your-robot.md).
#
#   tools/known-truth/recordings.sh ENGINE [OUT] [-- TUNE OPTIONS...]
#
# e.g. tools/known-truth/recordings.sh drake results/truth-drake
# An engine out of process needs its environment: `realitygap engines
# --install NAME`, or REALITYGAP_ENGINES_DIR=~/.cache/realitygap/engines-kit
# after `scripts/setup --tests`. Needs the release binary (`cargo build
# --release`); REALITYGAP overrides its path.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
engine="${1:?usage: tools/known-truth/recordings.sh ENGINE [OUT] [-- TUNE OPTIONS...]}"
shift
out="results/known-truth-recordings-$engine"
if [ $# -gt 0 ] && [ "$1" != "--" ]; then out="$1"; shift; fi
[ $# -gt 0 ] && [ "$1" = "--" ] && shift
bin="${REALITYGAP:-${CARGO_TARGET_DIR:-$root/target}/release/realitygap}"
[ -x "$bin" ] || { echo "no realitygap binary at $bin: run cargo build --release (or set REALITYGAP)" >&2; exit 2; }
fixtures="$root/third_party/fixtures/joint-recordings"
mkdir -p "$out"
out="$(cd "$out" && pwd)"
rm -rf "$out/real" "$out/tune"

"$bin" import rosbag "$fixtures"/mcap/episode_00{0,1,2,3} \
  --robot "$root/third_party/pybullet_data/kuka_iiwa/model.urdf" --out "$out/real" > "$out/import.log" 2>&1 \
  || { cat "$out/import.log" >&2; exit 1; }
python3 - "$fixtures/truth.json" "$out/known.toml" <<'PY'
import json, sys
truth = json.load(open(sys.argv[1]))
with open(sys.argv[2], "w") as f:
    for name, j in truth["joints"].items():
        f.write(f"[joints.{name}]\nkp = {j['kp']}\nkv = {j['kd']}\n")
PY
start=$(date +%s)
"$bin" tune --recordings "$out/real" --engine "$engine" --params "$out/known.toml" \
  --runs 1-2 --holdout 3-4 --out "$out/tune" "$@"
echo "tune: $(( $(date +%s) - start )) s"

python3 - "$fixtures/truth.json" "$out/tune/summary.json" "$out/table.md" <<'PY'
import json, sys
truth = json.load(open(sys.argv[1]))
summary = json.load(open(sys.argv[2]))
dt = truth["timestep_s"]
# Three readings of the truth: as written; the armature less dt kv (an
# engine whose velocity servo is implicit: MuJoCo's implicitfast, ODE);
# and the damping less dt kp as well (a PD spring evaluated at the step's
# end: Drake's implicit PD, Rapier with one substep).
readings = ["as written", "armature - dt kv", "and damping - dt kp"]
lines = ["| key | truth | fitted | 95 % interval | covers: " + " / ".join(readings) + " |",
         "|---|---:|---:|---|---|"]
params = summary["params"]
covered = [0] * len(readings)
for p in params:
    key, value = p["key"], p["value"]
    low, high = p.get("interval") or (None, None)
    if key == "controller.delay_s":
        t = truth["delay_s"]
        ts = [t, t, t]
    else:
        _, joint, what = key.split(".")
        j = truth["joints"][joint]
        t = j[what]
        arm = t - dt * j["kd"] if what == "armature" else t
        ts = [t, arm, arm - dt * j["kp"] if what == "damping" else arm]
    inside = [low is not None and low <= x <= high for x in ts]
    covered = [c + i for c, i in zip(covered, inside)]
    interval = f"[{low:.6g}, {high:.6g}]" if low is not None else "n/a"
    lines.append(f"| {key} | {t:.6g} | {value:.6g} | {interval} | "
                 + " / ".join("yes" if i else "no" for i in inside) + " |")
lines.append("")
lines.append(f"Intervals covering the truth, of {len(params)}: "
             + ", ".join(f"{c} {r}" for c, r in zip(covered, readings)) + ".")
text = "\n".join(lines) + "\n"
open(sys.argv[3], "w").write(text)
print(text)
PY
