#!/usr/bin/env bash
# Every benchmark table of the README's Results section (first block), then the tables of the experiment logs in
# docs/results/, in one go (not timed end to end).
# Needs ../shared (or VTD_SHARED_DIR). Generated sequences go to $BENCH_DIR (default: a temp folder).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
SHARED="${VTD_SHARED_DIR:-$(cd .. && pwd)/shared}"
BENCH_DIR="${BENCH_DIR:-$(mktemp -d)}"
ORACLE15='{"segmentation": {"source": "truth"}, "culling": {"culling": {"dilation_px": 15}}}'  # true masks, 15 px band
TEACHER="$SHARED/models/deeplabv3_257_mv_gpu.tflite"
echo "## generated sequences in $BENCH_DIR"
.venv/bin/vtdslam synth "$BENCH_DIR/synth" --frames 200 --people 2 > /dev/null
for seed in 1 2 3; do
    .venv/bin/vtdslam synth "$BENCH_DIR/synth$seed" --frames 200 --people 2 --seed "$seed" > /dev/null
done
.venv/bin/vtdslam synth "$BENCH_DIR/synth0" --frames 200 --people 0 > /dev/null  # the same room, people-free
.venv/bin/vtdslam augment "$SHARED/data/7scenes_redkitchen" --people-from "$SHARED/data/coco128_seg" \
    "$BENCH_DIR/aug" > /dev/null
SEEDS8=()
for seed in 0 1 2 3 4 5 6 7; do
    .venv/bin/vtdslam augment "$SHARED/data/7scenes_redkitchen" --people-from "$SHARED/data/coco128_seg" \
        "$BENCH_DIR/aug_s$seed" --frames 300 --seed "$seed" > /dev/null
    SEEDS8+=(--sequence "$BENCH_DIR/aug_s$seed:7scenes")
done

echo "# README, Results"
echo "## Bonn (evaluation only): every preset from frames 0, 2, 4 and 6, the teacher's masks beside"
$PY bench/bench_dynamic.py --sequence "$SHARED/data/bonn_crowd_dev:bonn" \
    --presets orb-only,geometry-only,no-restoration,full --starts 0,2,4,6 --summary --teacher "$TEACHER"
echo "## development sequences: eight augmented seeds, the synthetic room, static redkitchen (300 frames)"
$PY bench/bench_dynamic.py "${SEEDS8[@]}" --sequence "$BENCH_DIR/synth:tum3" \
    --sequence "$SHARED/data/7scenes_redkitchen:7scenes" --presets no-restoration --max-frames 300 --summary
echo "## synthetic rooms, seeds 0-3"
$PY bench/bench_dynamic.py --sequence "$BENCH_DIR/synth:tum3" --sequence "$BENCH_DIR/synth1:tum3" \
    --sequence "$BENCH_DIR/synth2:tum3" --sequence "$BENCH_DIR/synth3:tum3" --presets no-restoration \
    --max-frames 300 --summary
echo "## the true-mask oracle beside people-free and masks-removed (eight seeds)"
$PY bench/bench_dynamic.py "${SEEDS8[@]}" --presets no-restoration --max-frames 300 --summary --references \
    --config '{"segmentation": {"source": "truth"}}'
echo "## 7-Scenes redkitchen, 1000 frames"
$PY bench/bench_dynamic.py --sequence "$SHARED/data/7scenes_redkitchen:7scenes" --presets orb-only,no-restoration \
    --max-frames 1000
echo "## speed per stage"
$PY bench/bench_realtime.py --presets orb-only,geometry-only,no-restoration,full --no-orbslam3
echo "## MSNET on the real held-out sets"
$PY bench/bench_msnet.py --threads 1 --shared "$SHARED" --cache "$BENCH_DIR/msnet_cache"
echo "## restoration against the true background"
$PY bench/bench_inpainting.py "$BENCH_DIR/synth" $(for seed in 0 1 2 3 4 5 6 7; do echo "$BENCH_DIR/aug_s$seed"; done) \
    --frames 12 --references both-sided --unseen-fill harmonic,telea --speed

echo "# docs/results (experiment logs)"
echo "## SLAM core (7-Scenes redkitchen, 1000 frames)"; $PY bench/bench_slam.py
echo "## dynamic presets"
$PY bench/bench_dynamic.py --sequence "$BENCH_DIR/aug:7scenes" --sequence "$BENCH_DIR/synth:tum3" \
    --sequence "$SHARED/data/7scenes_redkitchen:7scenes" --max-frames 300
echo "## no-restoration with the true masks as segmentation and a 15 px band (separates culling's errors from MSNET's)"
$PY bench/bench_dynamic.py --sequence "$BENCH_DIR/aug:7scenes" --sequence "$BENCH_DIR/synth:tum3" \
    --presets no-restoration --max-frames 300 \
    --config "$ORACLE15"
$PY bench/bench_dynamic.py --sequence "$BENCH_DIR/synth:tum3" --presets no-restoration --max-frames 300 \
    --config '{"segmentation": {"source": "truth"}}'
echo "## five augmented sequences (seeds 0-4, first 300 frames): means and spread over people placements"
SEEDS=(--sequence "$BENCH_DIR/aug:7scenes")
for seed in 1 2 3 4; do SEEDS+=(--sequence "$BENCH_DIR/aug_s$seed:7scenes"); done
$PY bench/bench_dynamic.py "${SEEDS[@]}" --presets orb-only,no-restoration --max-frames 300 --summary --references
$PY bench/bench_dynamic.py "${SEEDS[@]}" --presets no-restoration --max-frames 300 --summary --config "$ORACLE15"
echo "## all eight seeds (0-7): MSNET with the references, and the true-mask oracle (no band change)"
$PY bench/bench_dynamic.py "${SEEDS8[@]}" --presets no-restoration --max-frames 300 --summary --references
$PY bench/bench_dynamic.py "${SEEDS8[@]}" --presets no-restoration --max-frames 300 --summary \
    --config '{"segmentation": {"source": "truth"}}'
echo "## bonn_crowd_dev (evaluation only): every preset, and the DeepLabV3 teacher as segmenter"
$PY bench/bench_dynamic.py --sequence "$SHARED/data/bonn_crowd_dev:bonn" \
    --presets orb-only,geometry-only,no-restoration,full --teacher "$SHARED/models/deeplabv3_257_mv_gpu.tflite"
echo "## real time: every preset, whole sequences, ORB-SLAM3 beside when pyorbslam3 is installed"
$PY bench/bench_realtime.py --presets orb-only,geometry-only,no-restoration,full
echo "## the synthetic room without people, and with the people's pixels cut out (--references)"
$PY bench/bench_dynamic.py --sequence "$BENCH_DIR/synth:tum3" --presets no-restoration --max-frames 300 --references
$PY bench/bench_dynamic.py --sequence "$BENCH_DIR/synth0:tum3" --presets orb-only,no-restoration --max-frames 300
echo "## the augmented sequence in full (1000 frames)"
$PY bench/bench_dynamic.py --sequence "$BENCH_DIR/aug:7scenes" --presets orb-only,no-restoration --max-frames 1000 \
    --references
$PY bench/bench_dynamic.py --sequence "$BENCH_DIR/aug:7scenes" --presets no-restoration --max-frames 1000 \
    --config "$ORACLE15"
# A setting's effect (its --config JSON): on the development means (eight seeds, the synthetic room, static
# redkitchen; 300 frames), on AUG 1000, and on Bonn with the teacher beside (evaluation only).
dev_means() { $PY bench/bench_dynamic.py "${SEEDS8[@]}" --sequence "$BENCH_DIR/synth:tum3" \
    --sequence "$SHARED/data/7scenes_redkitchen:7scenes" --presets no-restoration --max-frames 300 --summary \
    --config "$1"; }
aug1000() { $PY bench/bench_dynamic.py --sequence "$BENCH_DIR/aug:7scenes" --presets no-restoration \
    --max-frames 1000 --config "$1"; }
bonn() { $PY bench/bench_dynamic.py --sequence "$SHARED/data/bonn_crowd_dev:bonn" --presets "$2" \
    --teacher "$SHARED/models/deeplabv3_257_mv_gpu.tflite" --config "$1"; }
echo "## exclusion band with MSNET: 3 (default), 9, 15, 21 px on the development means; 15 px on AUG 1000 and Bonn"
for px in 3 9 15 21; do dev_means "{\"culling\": {\"culling\": {\"dilation_px\": $px}}}"; done
BAND15='{"culling": {"culling": {"dilation_px": 15}}}'
aug1000 "$BAND15"
bonn "$BAND15" no-restoration
echo "## mask memory (segmentation.memory_frames): 0, 1 (default), 2, 3 on the development means; 0 and 1 on AUG 1000 and Bonn"
for n in 0 1 2 3; do dev_means "{\"segmentation\": {\"memory_frames\": $n}}"; done
MEMORY0='{"segmentation": {"memory_frames": 0}}'
aug1000 '{}'
aug1000 "$MEMORY0"
bonn "$MEMORY0" no-restoration
echo "## per-object threshold on the development means and Bonn (frame level is the default)"
OBJECT='{"culling": {"culling": {"threshold": {"mode": "object"}}}}'
dev_means "$OBJECT"
bonn "$OBJECT" geometry-only,no-restoration
echo "## dense map: people in map.ply, with and without the mask memory, and the demo sequence"
$PY bench/bench_map.py --sequence "$BENCH_DIR/synth:tum3" --sequence "$BENCH_DIR/aug_s1:7scenes" --methods points+carve
$PY bench/bench_map.py --sequence "$BENCH_DIR/synth:tum3" --sequence "$BENCH_DIR/aug_s1:7scenes" --methods points+carve \
    --config "$MEMORY0"
.venv/bin/vtdslam synth "$BENCH_DIR/demo" --frames 150 --people 2 > /dev/null
$PY bench/bench_map.py --sequence "$BENCH_DIR/demo:tum3" --methods points,points+carve
echo "## carving: every 3rd frame, three views (default) against keyframes with two views and the majority rule;"
echo "## on Bonn (evaluation only) people from the 513 teacher's masks"
BONN_MAP=(--sequence "$SHARED/data/bonn_crowd_dev:bonn" --max-frames 314
          --references "$SHARED/models/deeplabv3_mnv2_pascal_quant.tflite")
$PY bench/bench_map.py "${BONN_MAP[@]}" --methods points,points+carve
KF_TWO='{"dense": {"carve_every": 0, "carve_min_through": 2}}'
KF_MAJORITY='{"dense": {"carve_every": 0, "carve_min_through": 2, "carve_majority": true}}'
for extra in "$KF_TWO" "$KF_MAJORITY"; do
    $PY bench/bench_map.py "${BONN_MAP[@]}" --methods points+carve --config "$extra"
done
SEQ0="$BENCH_DIR/aug_s0:7scenes"
for extra in '{}' "$KF_TWO" "$KF_MAJORITY"; do
    $PY bench/bench_map.py --sequence "$BENCH_DIR/synth:tum3" --sequence "$BENCH_DIR/demo:tum3" \
        --sequence "$BENCH_DIR/aug_s1:7scenes" --sequence "$SEQ0" --sequence "$SHARED/data/7scenes_redkitchen:7scenes" \
        --methods points+carve --config "$extra"
done
echo "## culling cost"; $PY bench/bench_culling.py "$BENCH_DIR/aug" --camera 7scenes --frames 60
echo "## culling cost inside a run on real frames (Bonn, shipped MSNET)"; $PY bench/bench_culling.py "$SHARED/data/bonn_crowd_dev" --camera bonn --pipeline no-restoration
echo "## restoration"; $PY bench/bench_inpainting.py "$BENCH_DIR/synth" "$BENCH_DIR/aug" --frames 15 --camera 7scenes --speed
echo "## MSNET"
$PY bench/bench_msnet.py --threads 1 --sequence "$BENCH_DIR/aug" \
    $(for seed in 1 2 3 4; do echo --sequence "$BENCH_DIR/aug_s$seed"; done)
echo "## MSNET's refinement factorised: ranks 1 and 2 from the dense checkpoint of git 263e745 (MODEL_CARD.md)"
git show 263e745:worker/slam/segmentation/weights/msnet_default.pt > "$BENCH_DIR/msnet_dense.pt"
for rank in 1 2; do
    .venv/bin/vtdslam compress-msnet "$BENCH_DIR/msnet_dense.pt" "$BENCH_DIR/msnet_r$rank.pt" --rank "$rank"
done
for ckpt in dense r1 r2; do $PY bench/bench_msnet.py --threads 1 --checkpoint "$BENCH_DIR/msnet_$ckpt.pt"; done
echo "## non-person movers (animals; vehicles and objects; parked objects beside them) next to the people seeds 0-3"
MOVERS=()
for seed in 0 1 2 3; do
    for kind in animal vehicle,object; do
        .venv/bin/vtdslam augment "$SHARED/data/7scenes_redkitchen" --people-from "$SHARED/data/coco128_seg" \
            "$BENCH_DIR/movers_${kind/,/_}_s$seed" --frames 300 --seed "$seed" --movers "$kind" --static 2 \
            --static-classes object > /dev/null
        MOVERS+=(--sequence "$BENCH_DIR/movers_${kind/,/_}_s$seed:7scenes")
    done
done
$PY bench/bench_movers.py "${MOVERS[@]}" --presets orb-only,geometry-only,no-restoration,full --max-frames 300
$PY bench/bench_movers.py $(for seed in 0 1 2 3; do echo --sequence "$BENCH_DIR/aug_s$seed:7scenes"; done) \
    --presets no-restoration,full --max-frames 300
echo "## generators"; $PY bench/bench_generators.py --frames 90
echo "## upload"; $PY bench/bench_upload.py
