#!/bin/sh
# Regenerates the `sepmem synth` fixture bags (deterministic: same binary
# version and seed give the same bytes). Run from the repository root.
set -e
SEPMEM=${SEPMEM:-target/release/sepmem}
D=tests/data/bags
# (a) one moving, rotating ellipsoid on its own topic, Kinect noise (1 % outliers);
#     legacy point budget (the focal length is chosen for ~2500 points).
"$SEPMEM" synth -o "$D/synth_ellipsoid.mcap" --shapes ellipsoid --frames 12 \
    --points 2500 --noise kinect --mesh-res 24 --seed 1 --quiet
# (b) a bottle and a torus as labelled segments of one coloured cloud, 3 % outliers.
"$SEPMEM" synth -o "$D/synth_two_labelled.mcap" --shapes bottle,torus --labels \
    --topic /synth/points --colour --outliers 0.03 --frames 12 --points 2500 \
    --noise kinect --mesh-res 24 --seed 2 --quiet
# (c) sensor-true: a mug turning 180° in place over 30 frames, seen by the
#     default 640×480, f = 525 camera at 1 m, Kinect noise, no outliers.
"$SEPMEM" synth -o "$D/synth_turn_mug.mcap" --shapes mug --motion turn --degrees 180 \
    --frames 30 --distance 1.0 --noise kinect --outliers 0 --mesh-res 48 --seed 4 --quiet
