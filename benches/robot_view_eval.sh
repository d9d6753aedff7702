#!/usr/bin/env bash
# The robot's-view evaluation of issue 20 used to choose the warm enclosure,
# the refit and the fused completion: 8 sequences beside the committed
# robot_view bags (with them, the "15" of the first measurements), a can
# turning and orbited, 8 held out, and 16 more (8 shapes turning and
# orbited at other noise seeds), replayed with `sepmem replay -q`
# and summarised (median last-third F, volume IoU, largest volume ratio, cold
# frames after the first, share of visible points > 3 sigma outside, seen
# side, the tracked pose's ADD-S over the last third in mm, and the largest
# silhouette excess of a frame's mesh in earlier views).
#
# Beside them, and summarised apart ("faults", not in "all"): 18 sequences
# with a real sensor's faults (the Kinect model's 1 % outliers; the orbited
# ones also flying pixels on 30 % of the depth edges), the 9 shapes turning
# and orbited, and the committed bags with faults (turn_capsule_faults,
# turn_capsule_detached). Since pipeline.model.confirm.
#
#   benches/robot_view_eval.sh [OUT_DIR] [-- replay args, e.g. --set key=value]
#
# Needs a release build (cargo build --release) and, for the YCB banana, the
# shared datasets (../shared/datasets).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-/tmp/sepmem-robot-view}; shift || true
[ "${1:-}" = "--" ] && shift
S=target/release/sepmem
YCB=${YCB:-../shared/datasets/meshes_ground_truth/ycb_video_simplified/YcbBanana.obj}
mkdir -p "$OUT/bags" "$OUT/runs"
CAM="--width 480 --height 360 --focal 393.75 --distance 1.0 --noise kinect --outliers 0 --frames 30 --degrees 180 --quiet"
KIN="--noise kinect --outliers 0 --frames 30 --quiet"
b="$OUT/bags"
# The 8 beside the committed bags (tuned on).
$S synth -o "$b/t_turn_mug.mcap" --shapes mug --motion turn $CAM --mesh-res 48 --seed 5
for shape in bottle ellipsoid torus; do
    $S synth -o "$b/t_turn_$shape.mcap" --shapes $shape --motion turn $CAM --mesh-res 32 --seed 5
done
$S synth -o "$b/t_orbit_rounded_box.mcap" --shapes rounded_box --motion orbit $CAM --mesh-res 32 --seed 8
$S synth -o "$b/t_orbit_capsule.mcap" --shapes capsule --motion orbit $CAM --mesh-res 32 --seed 8
$S synth -o "$b/t_turn_rounded_box.mcap" --shapes rounded_box --motion turn $CAM --mesh-res 32 --seed 9
$S synth -o "$b/t_turn_bent_tube.mcap" --shapes bent_tube --motion turn $CAM --mesh-res 32 --seed 9
# A can turning and orbited (since membrane.view.revolution's axis test:
# a can's rings are all alike).
$S synth -o "$b/t_turn_can.mcap" --shapes can --motion turn $CAM --mesh-res 32 --seed 5
$S synth -o "$b/t_orbit_can.mcap" --shapes can --motion orbit $CAM --mesh-res 32 --seed 8
if [ -f "$YCB" ]; then
    $S synth -o "$b/t_orbit_banana.mcap" --shapes "$YCB" --motion orbit $CAM --seed 8
else
    echo "SKIPPED the orbited YCB banana: $YCB not found" >&2
fi
cp tests/data/bags/robot_view/*.mcap "$b/"
# The 8 held out (default camera, 640x480, f 525).
$S synth -o "$b/h_sphere_turn.mcap" --shapes sphere --motion turn --distance 0.8 --seed 11 $KIN
$S synth -o "$b/h_bowl_turn.mcap" --shapes bowl --motion turn --seed 12 $KIN
$S synth -o "$b/h_capsule_far.mcap" --shapes capsule --motion turn --distance 1.3 --seed 13 --mesh-res 32 $KIN
$S synth -o "$b/h_box_orbit_near.mcap" --shapes rounded_box --motion orbit --distance 0.8 --seed 14 $KIN
$S synth -o "$b/h_bottle_orbit.mcap" --shapes bottle --motion orbit --seed 15 $KIN
$S synth -o "$b/h_mug_orbit.mcap" --shapes mug --motion orbit --seed 16 $KIN
$S synth -o "$b/h_tube_pick.mcap" --shapes bent_tube --motion pick --seed 18 --mesh-res 32 $KIN
$S synth -o "$b/h_ell_360.mcap" --shapes ellipsoid --motion turn --degrees 360 --seed 17 $KIN
# 16 more (since the 39-sequence measurement of membrane.step.facing_away):
# 8 shapes turning and orbited, at other noise seeds; the medians of 15 or 8
# sequences moved by +-0.03 between settings that changed little.
seed=30
for shape in capsule rounded_box bent_tube ellipsoid bottle sphere torus mug; do
    for motion in turn orbit; do
        seed=$((seed + 1))
        res=32; [ "$shape" = mug ] && res=48
        $S synth -o "$b/x_${motion}_$shape.mcap" --shapes $shape --motion $motion $CAM --mesh-res $res --seed $seed
    done
done
# The 18 with a sensor's faults.
FAULTS="--width 480 --height 360 --focal 393.75 --distance 1.0 --noise kinect --frames 30 --degrees 180 --quiet"
for shape in capsule rounded_box bent_tube bottle ellipsoid mug torus can banana; do
    res=32; [ "$shape" = mug ] && res=48
    s1=21; s2=22; src=$shape
    if [ "$shape" = banana ]; then
        s1=23; s2=24; src=$YCB
        [ -f "$YCB" ] || { echo "SKIPPED the YCB banana with faults: $YCB not found" >&2; continue; }
    fi
    $S synth -o "$b/s_turn_$shape.mcap" --shapes "$src" --motion turn $FAULTS --mesh-res $res --seed $s1
    $S synth -o "$b/s_orbit_$shape.mcap" --shapes "$src" --motion orbit $FAULTS --mesh-res $res --seed $s2 --flying-pixels 0.3
done
# 18 close up, summarised apart ("close", not in "all"): the 9 shapes
# turning and orbited 0.55 m from the default camera (640x480, f 525),
# 4-35 k points a frame, where a robot grasps (since detached::Known and
# the revolution's tolerance beside a silhouette).
seed=30
for shape in capsule rounded_box bent_tube ellipsoid bottle can torus sphere mug; do
    res=32; [ "$shape" = mug ] && res=48
    for motion in turn orbit; do
        seed=$((seed + 1))
        $S synth -o "$b/c_${motion}_$shape.mcap" --shapes $shape --motion $motion $KIN --distance 0.55 --mesh-res $res --seed $seed
    done
done
export S OUT
ls "$b"/*.mcap | xargs -P "$(nproc)" -I@@ sh -c '"$S" replay "@@" -q '"$*"' > "$OUT/runs/$(basename "@@" .mcap).txt" 2>&1'
python3 - "$OUT/runs" <<'PY'
import glob, os, re, statistics as st, sys
rows, missing = {}, []
for f in sorted(glob.glob(sys.argv[1] + "/*.txt")):
    t = open(f).read()
    m = re.search(r"last third \(\d+\): F ([\d.]+) seen side [\d.]+ IoU ([\d.]+)", t)
    # A collapsed mesh can hold a (slightly) negative volume.
    v = re.search(r"volume ratio min -?[\d.]+ max ([\d.]+)", t)
    c = re.search(r"\((\d+) warm, (\d+) cold\)", t)
    o = re.search(r"outside by > 3 sigma (\d+) of (\d+)", t)
    s = re.search(r"seen side median ([\d.]+)", t)
    # The tracked pose's ADD-S over the last third (mm).
    a = re.search(r"last third \(\d+\): [^;]*ADD-S ([\d.]+)", t)
    # The largest silhouette excess of any frame's mesh in earlier views.
    x = re.search(r"in earlier views median [\d.]+ max ([\d.]+)", t)
    if not (m and v and c and o and s and a and x):
        missing.append(os.path.basename(f)); continue
    name = os.path.basename(f)[:-4]
    r = (float(m[1]), float(m[2]), float(v[1]), int(c[2]) - 1, int(o[1]) / int(o[2]), float(s[1]), float(a[1]), float(x[1]))
    rows[name] = r
    print(f"{name:24} F {r[0]:.3f} IoU {r[1]:.3f} vmax {r[2]:.2f} cold {r[3]} out3 {r[4]:.3f} seen {r[5]:.3f} adds {r[6]:.2f} pastex {r[7]:.3f}")
faulty = lambda n: n.startswith("s_") or n.endswith(("_faults", "_detached"))
close = lambda n: n.startswith("c_")
groups = (
    ("tuned", lambda n: not n.startswith(("h_", "x_", "c_")) and not faulty(n)),
    ("held out", lambda n: n.startswith("h_")),
    ("more", lambda n: n.startswith("x_")),
    ("all", lambda n: not faulty(n) and not close(n)),
    ("faults", faulty),
    ("close", close),
)
for label, keep in groups:
    sel = [r for n, r in rows.items() if keep(n)]
    if sel:
        med = lambda k: st.median(x[k] for x in sel)
        print(f"{label} ({len(sel)}): median F {med(0):.3f} (mean {st.mean(x[0] for x in sel):.3f}) IoU {med(1):.3f} "
              f"vmax {med(2):.2f} cold {sum(x[3] for x in sel)} out3 {med(4):.3f} seen {med(5):.3f} adds {med(6):.2f} mm pastex {med(7):.3f}")
if missing:
    # The medians above leave these out: a replay that failed or whose
    # summary this script cannot read.
    sys.exit(f"NO SUMMARY for {len(missing)} sequence(s): {', '.join(missing)}")
PY
