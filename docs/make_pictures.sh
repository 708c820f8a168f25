#!/usr/bin/env bash
# Regenerates the pictures in docs/ (the default anny left arm, weight 0.5 -> 7.5 mm tissue).
set -euo pipefail
cd "$(dirname "$0")"
# Scenes at forces the FEM and the shipped models carry (0.05..0.5 N)
stmpl scene --load disk --force 0.3 --radius 25 --at 0.5 0.5 --out arm_disk.png
stmpl scene --load seam_disk --force 0.3 --radius 30 --along 0.5 --out arm_seam_disk.png
stmpl scene --load band --force 0.5 --width 30 --along 0.4 --out arm_band.png
stmpl scene --load letter --char A --force 0.3 --char-height 170 --width 18 --at 0.5 0.5 \
    --out arm_letter_A.png
# FEM: 0.4 N on a 2 cm disk, reference mesh, 4 continuation levels
stmpl solve --load disk --force 0.4 --levels 4 --radius 20 --at 0.5 0.5 --out arm_fem_disk.png
# The main job: anny's hand squeezing the layered forearm with 5 N, against the FEM
stmpl simulate --compare --out-dir /tmp/stmpl_grip && cp /tmp/stmpl_grip/simulate.png simulate_grip.png
# The paper's gel on the shipped models' skin (the once-subdivided arm): the grasp, the letters
# and a pinch, each against the FEM (solved on the patch each contact moves)
stmpl simulate --compare --fidelity auto --model zoo:gnn_arm_fine --model zoo:uv_unet_arm_fine \
    --model zoo:linear_arm_fine --model zoo:naive_arm_fine --out-dir /tmp/stmpl_grasp \
    && cp /tmp/stmpl_grasp/simulate.png simulate_grasp.png
stmpl simulate --letters ECCV --force 0.3 --depth 3 --compare --fidelity auto \
    --out-dir /tmp/stmpl_eccv && cp /tmp/stmpl_eccv/simulate.png simulate_eccv.png
stmpl simulate --tissue paper --grip pinch --along 0.5 --around 0.5 --force 0.15 --compare \
    --fidelity auto \
    --out-dir /tmp/stmpl_pinch && cp /tmp/stmpl_pinch/simulate.png simulate_pinch.png
# The belly under anny's open hand (0.2 N, --depth 4), answered by the belly's own models
stmpl simulate --part belly --force 0.2 --depth 4 --compare --fidelity auto \
    --model zoo:gnn_belly_bodies --model zoo:uv_unet_belly_bodies --model zoo:linear_belly_bodies \
    --out-dir /tmp/stmpl_belly && cp /tmp/stmpl_belly/simulate.png simulate_belly.png
