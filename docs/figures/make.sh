#!/usr/bin/env bash
# Regenerates every committed figure in docs/figures/ from the current code: the twin's
# offline flights (`firmware-sim simulate`) drawn by `vtol-gcs log plot` in the paper's frame,
# a transition flown in lockstep, and the airframe's lift and drag polar. Deterministic: the
# flights are seeded, so an unchanged model redraws the same pictures. Run from anywhere: docs/figures/make.sh
set -euo pipefail

root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root"
figures=docs/figures
cargo build --quiet -p vtol-gcs -p firmware-sim --bins
bin=${CARGO_TARGET_DIR:-$root/target}/debug
sim=$bin/firmware-sim
plot() { "$bin/vtol-gcs" log plot "$@"; }

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# Figs. 3-5: the paper's initial conditions in `paper` mode, to hover at (0, 0, 1) (HOVER_ALT).
"$sim" simulate --model paper --initial phi=0.1,theta=0.1,psi=1,x=0.1,y=0.1,z=0.1 \
    --csv "$work/paper.csv"
plot "$work/paper.csv" --frame paper --kind attitude -o "$figures/fig3_attitude.png" \
    --size 900x800 --title "Fig. 3: attitude (twin, paper mode)"
plot "$work/paper.csv" --frame paper --kind position -o "$figures/fig4_position.png" \
    --size 900x800 --setpoint 0,0,1 --title "Fig. 4: position (twin, paper mode)"
plot "$work/paper.csv" --frame paper --kind inputs -o "$figures/fig5_inputs.png" \
    --size 900x1000 --title "Fig. 5: control inputs (twin, paper mode)"

# Figs. 8-10: a 200 ms torque push at t = 2 s on one axis, in QSTABILIZE at 4 m (`physical`).
for spec in "8 roll roll=0.1@2" "9 pitch pitch=0.1@2" "10 yaw yaw=0.05@2"; do
    read -r n axis push <<<"$spec"
    "$sim" simulate --mode QSTABILIZE --initial z=4 --duration 8 --push "$push" \
        --csv "$work/$axis.csv"
    plot "$work/$axis.csv" --frame paper --kind attitude \
        -o "$figures/fig${n}_${axis}_attitude.png" --size 640x700 \
        --title "Fig. $n: $axis push, attitude"
    plot "$work/$axis.csv" --frame paper --kind pwm -o "$figures/fig${n}_${axis}_pwm.png" \
        --size 640x700 --title "Fig. $n: $axis push, PWM"
done

# A forward transition, level flight on the wing and a back transition (README, docs/forward-flight.md):
# the twin in lockstep flown with pymavlink (the venv tests/run.sh makes, or $PYTHON).
FIRMWARE_SIM_BIN=$sim "${PYTHON:-$root/.venv/bin/python}" docs/figures/transition_flight.py \
    "$work/transition.tlog"
plot "$work/transition.tlog" --kind transition -o "$figures/transition.png" --size 760x1000 \
    --title "A transition, 30 s on the wing, and back (twin, physical mode)"

# The aerodynamic model's C_L, C_D and L/D over 0-90° (docs/model.md).
cargo run --quiet -p firmware-sim --example aero_polar -- "$figures/aero_lift_drag.png"
