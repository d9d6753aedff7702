#!/bin/sh
# Regenerates the `sepmem synth` fixture bags (deterministic: same binary
# version and seed give the same bytes). Run from the repository root.
set -e
SEPMEM=${SEPMEM:-target/release/sepmem}
D=tests/data/bags
# (a) one moving, rotating ellipsoid on its own topic, Kinect noise (1 % outliers).
"$SEPMEM" synth -o "$D/synth_ellipsoid.mcap" --shapes ellipsoid --frames 12 \
    --points 2500 --noise kinect --mesh-res 24 --seed 1 --quiet
# (b) a bottle and a torus as labelled segments of one coloured cloud, 3 % outliers.
"$SEPMEM" synth -o "$D/synth_two_labelled.mcap" --shapes bottle,torus --labels \
    --topic /synth/points --colour --outliers 0.03 --frames 12 --points 2500 \
    --noise kinect --mesh-res 24 --seed 2 --quiet
