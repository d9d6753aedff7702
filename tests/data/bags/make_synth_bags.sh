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
# (d) the robot's view (issue 20): the shapes, a bottle, a ball and a can turning 180° in
#     place over 30 frames (6° per frame), one orbited by the camera, and three swapped on
#     one stream; a 480×360, f = 393.75 camera (the default's field of view at
#     0.56× its points, to keep the bags small) at 1 m, Kinect noise, no outliers.
#     The YCB banana is read from the shared datasets (LGPL-2.1, see README).
YCB=${YCB:-../shared/datasets/meshes_ground_truth/ycb_video_simplified}
R="$D/robot_view"
mkdir -p "$R"
CAM="--width 480 --height 360 --focal 393.75 --distance 1.0 --noise kinect --outliers 0 --frames 30 --degrees 180"
for shape in capsule rounded_box bent_tube bottle; do
    "$SEPMEM" synth -o "$R/turn_$shape.mcap" --shapes $shape --motion turn $CAM --mesh-res 32 --seed 4 --quiet
done
# A ball 0.12 m across (at 0.2 m its bag was 1.6 MB), and a can 0.12 m tall.
for shape in sphere can; do
    "$SEPMEM" synth -o "$R/turn_$shape.mcap" --shapes $shape --motion turn $CAM --mesh-res 32 --size 0.12 --seed 4 --quiet
done
"$SEPMEM" synth -o "$R/turn_ycb_banana.mcap" --shapes "$YCB/YcbBanana.obj" --motion turn $CAM --seed 4 --quiet
"$SEPMEM" synth -o "$R/orbit_bent_tube.mcap" --shapes bent_tube --motion orbit $CAM --mesh-res 32 --seed 7 --quiet
"$SEPMEM" synth -o "$R/orbit_ycb_banana.mcap" --shapes "$YCB/YcbBanana.obj" --motion orbit $CAM --seed 8 --quiet
"$SEPMEM" synth -o "$R/swap.mcap" --shapes rounded_box,bottle,mug --motion swap $CAM --mesh-res 48 --seed 4 --quiet
# (e) a real sensor's faults: the capsule turning as in (d), with the Kinect model's
#     1 % outliers and flying pixels on 30 % of the depth edges' pixels.
"$SEPMEM" synth -o "$R/turn_capsule_faults.mcap" --shapes capsule --motion turn \
    --width 480 --height 360 --focal 393.75 --distance 1.0 --noise kinect --frames 30 \
    --degrees 180 --flying-pixels 0.3 --mesh-res 32 --seed 4 --quiet
# (f) turn_capsule_detached.mcap, the first 10 frames of turn_capsule.mcap with a patch of
#     points 0.6 m behind the capsule: tests/python/add_detached.py (Python rosbags).
# (g) objects that hide one another: a can and a torus in one labelled cloud, the camera
#     orbiting both by 360° (a 320×240, f = 262.5 camera, the default field of view at a
#     quarter of its points), so each passes behind the other.
"$SEPMEM" synth -o "$R/occluded_orbit.mcap" --shapes can,torus --motion orbit --degrees 360 \
    --width 320 --height 240 --focal 262.5 --distance 1.0 --noise kinect --outliers 0 \
    --frames 30 --labels --mesh-res 32 --seed 6 --quiet
