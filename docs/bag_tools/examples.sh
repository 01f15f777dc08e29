#!/usr/bin/env bash
# Print every example of docs/BAG_TOOLS.md from real runs of its commands.
#   source scripts/env.sh; bash docs/bag_tools/examples.sh /tmp/bt24
# (python3 scripts/doc_examples.py BAG_TOOLS.md runs it and writes the output into the doc.)
# Records the three paper objects (grasp_demo), an excitation (excite) and a bag killed with
# kill -9, writes the edited configs the examples use, then runs bag_info, bag_analyze,
# bag_replay (publish, --resimulate, --closed-loop, --sweep) and bag_identify on them.
# Each command is printed as "$ command", then its output, then "[exit N]".
set -uo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
OUT="${1:?usage: examples.sh OUTPUT_FOLDER}"
export PATH="$ROOT/install/gripper_ros/lib/gripper_ros:$PATH"
CONFIG="$ROOT/install/gripper_ros/share/gripper_ros/config/gripper.yaml"
rm -rf "$OUT/bt_bags" "$OUT/bt_killed"
mkdir -p "$OUT/bt_bags" "$OUT/bt_killed"
cd "$OUT/bt_bags" || exit 1

run() { echo "\$ $*"; bash -c "$*" 2>&1; echo "[exit $?]"; }
edit() {  # edit NAME OLD NEW: the installed config with one value changed
  python3 - "$CONFIG" "$@" <<'PY'
import pathlib, sys
config, name, old, new = sys.argv[1:]
text = pathlib.Path(config).read_text()
assert text.count(old) == 1, old
pathlib.Path(name).write_text(text.replace(old, new))
PY
}

run "grasp_demo --output $OUT/bt_bags 2>&1 | grep -v '^\[INFO\]'"
mapfile -t BAGS < <(ls -d grasp_*/ | tr -d /)
B1=${BAGS[0]} B2=${BAGS[1]} B3=${BAGS[2]}
edit impact_0.9.yaml 'impact_force_fraction: 0.45 ' 'impact_force_fraction: 0.9  '
edit mpc_pd_kc500.yaml 'mpc_pd: {kc: 968.0,' 'mpc_pd: {kc: 500.0,'
edit unstable.yaml 'closed_loop_pole: 0.35' 'closed_loop_pole: 1.2'
printf 'plant:\n  gear_ratio: [1, 2\n' > broken.yaml
mkdir -p not_a_bag && printf 'hello' > not_a_bag/x.mcap

echo '## bag_info'
run bag_info "$B2"
echo '## bag_analyze'
run bag_analyze "$B1" "$B2" "$B3" --plot analysis.png
run "bag_analyze $B2 --json | head -8"
run "bag_analyze $B2 --csv | cut -c1-100"
echo '## bag_replay (publish), each with a listener told to stop once the replay has ended'
for args in '--rate 1 -q' '--rate 5 -q'; do
  python3 "$HERE/replay_listener.py" > listener.txt & listener=$!
  run bag_replay "$B2" --topics /gripper/joint_states $args --wait-for-subscribers 1
  kill -INT "$listener"; wait; cat listener.txt
done
python3 "$HERE/replay_listener.py" > listener.txt & listener=$!
run "bag_replay $B2 --topics /gripper/joint_states --clock --rate 5 --wait-for-subscribers 1 2>&1 | tr '\r' '\n' | sed 's/\x1b\[K//' | tail -2"
kill -INT "$listener"; wait; cat listener.txt
python3 "$HERE/replay_listener.py" --stop-at-first > listener.txt & listener=$!
run bag_replay "$B2" --topics /gripper/joint_states --rate 5 -q --wait-for-subscribers 1 --wait-for-all-acked 1000
kill -CONT "$listener"; kill -INT "$listener"; wait; cat listener.txt
echo '## --resimulate'
for b in "$B1" "$B2" "$B3"; do run bag_replay "$b" --resimulate; done
run bag_replay "$B2" --resimulate impact_0.9.yaml
run bag_replay "$B2" --resimulate mpc_pd_kc500.yaml
run "bag_replay $B2 --resimulate --force-controller mpc_pi | tail -6"
run bag_replay "$B2" --resimulate impact_0.9.yaml --json
echo '## --closed-loop'
run bag_replay "$B2" --resimulate --closed-loop
run bag_replay "$B2" --resimulate --closed-loop --set force_control.contact_aware.impact_force_fraction=0.9 --plot whatif.png
run bag_replay "$B2" --resimulate --closed-loop --sweep force_control.contact_aware.impact_force_fraction=0.1,0.45,0.9
run bag_replay "$B2" --resimulate --closed-loop --sweep position_control.mpc_pd.kc=500,968,1500
echo '## bag_identify'
run "excite --output . 2>&1 | grep -v '^\[INFO\]'"
E=$(ls -d excite_*/ | tr -d / | head -1)
run bag_identify "$E" "$B2" --output identified.yaml --plot identify_fit.png
run bag_identify "$B2"
echo '## bad input'
run bag_info nope
run bag_analyze not_a_bag
run bag_info not_a_bag/x.mcap
run bag_analyze "$B2" --plot out.pdf
run bag_replay "$B2" --topics /nope
run bag_replay "$B2" --rate 0
run bag_replay nope --resimulate
run bag_replay not_a_bag --resimulate
run bag_replay "$B2" --resimulate --approach-force-margin -1
run bag_replay "$B2" --resimulate missing.yaml
run bag_replay "$B2" --resimulate broken.yaml
run bag_replay "$B2" --resimulate unstable.yaml
run bag_replay "$B2" --resimulate --closed-loop --set position_control.mpc_pd.kc=-1
run bag_replay "$B2" --resimulate --closed-loop --sweep position_control.mpc_pd.kx=1,2
run bag_identify not_a_bag
echo '## interoperability'
run python3 "$HERE/interop.py" "$B2"
run head -32 "$B2/metadata.yaml"
run "sed -n '/custom_data:/,\$p' $B2/metadata.yaml | cut -c1-120"

echo '## a bag killed with kill -9 during a realtime grasp'
cd "$OUT/bt_killed" || exit 1
grasp_demo --width 0.05 --mass 1.69 --time-mode realtime --output "$OUT/bt_killed" --no-plot \
  > demo.log 2>&1 &
pid=$!
for _ in $(seq 200); do compgen -G 'grasp_*' > /dev/null && break; sleep 0.05; done
sleep 3.0
kill -9 "$pid"; wait "$pid" 2>/dev/null
K=$(ls -d grasp_*/ | tr -d / | head -1)
run bag_info "$K"
run bag_replay "$K" --resimulate
run "bag_analyze $K > /dev/null"
