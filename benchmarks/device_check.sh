#!/usr/bin/env bash
# One short GPU session, all figures and the trained generator in one folder ($OUT, default device_out):
#   1. GAN seconds per iteration at the paper's settings (6144 quads, 2 shapes x 8 views, 256 px) and at
#      the CPU default (2 x 4 views, 128 px): benchmarks/bench_gan_step.py
#   2. a chair-world GAN run of TRAIN_MINUTES minutes (64 px, the shipped model's config) with snapshots,
#      then its learning curve through the generation protocol: benchmarks/learning_curve_gan.py
#   3. texture transfer timing: benchmarks/bench_transfer.py
#   4. rendering on the device against the CPU (8 views at 256 and 512 px, forward and backward, and their
#      agreement): benchmarks/bench_render_device.py
#   5. the cellular automaton: a NCA_ITERS-iteration train nca on a stripes exemplar, its seconds per
#      iteration, and its quality and step time: benchmarks/nca_quality.py
# Runs in under 10 minutes on one H200 with the defaults; on a CPU it runs too (slowly: lower TRAIN_MINUTES).
#   OUT=device_out TRAIN_MINUTES=4 bash benchmarks/device_check.sh
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-device_out}
TRAIN_MINUTES=${TRAIN_MINUTES:-4}
NCA_ITERS=${NCA_ITERS:-300}
DEVICE=${DEVICE:-auto}
PY=${PYTHON:-python3}
mkdir -p "$OUT"
export MESH2TEX_PROGRESS=0
log() { echo "== $(date +%T) $*" | tee -a "$OUT/log.txt"; }
{ nvidia-smi --query-gpu=name,memory.total --format=csv 2>/dev/null || echo "no nvidia-smi"; $PY -c "import torch; print('torch', torch.__version__, 'cuda', torch.cuda.is_available())"; } > "$OUT/device.txt" 2>&1

if ! $PY -c "import mesh2tex" 2>/dev/null; then
  log "installing"
  $PY -m pip install -q -e . >> "$OUT/log.txt" 2>&1
fi

log "rendering on the device against the CPU"
$PY benchmarks/bench_render_device.py --repeats 10 > "$OUT/render_device.txt" 2>&1 || true

log "GAN step at the paper's settings"
$PY benchmarks/bench_gan_step.py --device "$DEVICE" --faces 6144 --batch 2 --views 8 --resolution 256 --iters 6 \
  > "$OUT/gan_step_paper.txt" 2>&1
log "GAN step at the CPU default"
$PY benchmarks/bench_gan_step.py --device "$DEVICE" --iters 6 > "$OUT/gan_step_default.txt" 2>&1

log "chair world"
W="$OUT/work"
$PY -m mesh2tex prepare synthetic --out "$W/world" --category chair --shapes 32 --views 8 --query-shapes 8 --seed 0 >> "$OUT/log.txt" 2>&1
TRAIN=$($PY -c "import json,sys; d=json.load(open('$W/world/index.json')); print(' '.join('$W/world/meshes/%s.obj'%n for n in d['split']['train_shapes']))")
QUERY=$($PY -c "import json,sys; d=json.load(open('$W/world/index.json')); print(' '.join('$W/world/meshes/%s.obj'%n for n in d['split']['query_shapes']))")
$PY -m mesh2tex prepare shapes --input $TRAIN --out "$W/shapes/train" --faces 1536 --levels 4 --workers 8 --seed 0 >> "$OUT/log.txt" 2>&1
$PY -m mesh2tex prepare shapes --input $QUERY --out "$W/shapes/query" --faces 1536 --levels 4 --workers 8 --seed 0 >> "$OUT/log.txt" 2>&1

log "GAN run of $TRAIN_MINUTES minutes"
cat > "$OUT/gan.yaml" <<EOF
sample_every: 500
checkpoint_every: 250
snapshot_every: 250
log_every: 10
generator: {encoder_channels: [32, 48, 64, 64], synthesis_channels: [32, 48, 64, 64]}
discriminator: {channel_base: 1024}
optim: {lr_field: 0.0012}
EOF
timeout $((TRAIN_MINUTES * 60)) $PY -m mesh2tex train gan --shapes "$W/shapes/train" --images "$W/world" --out "$OUT/gan" \
  --config "$OUT/gan.yaml" --iters 100000 --resolution 64 --views 4 --seed 0 --device "$DEVICE" >> "$OUT/log.txt" 2>&1
log "learning curve"
$PY benchmarks/learning_curve_gan.py --run "$OUT/gan" --world "$W/world" --shapes "$W/shapes/query" --json "$OUT/curve.json" \
  > "$OUT/curve.txt" 2>&1
log "transfer timing"
$PY benchmarks/bench_transfer.py > "$OUT/transfer.txt" 2>&1 || true
log "cellular automaton: $NCA_ITERS iterations"
$PY -c "from mesh2tex.synthetic.exemplars import exemplar_image; from mesh2tex.io.images import save_png; save_png('$OUT/stripes.png', exemplar_image('stripes', 128))"
$PY -m mesh2tex train nca --exemplar "$OUT/stripes.png" --out "$OUT/nca" --iters "$NCA_ITERS" --device "$DEVICE" >> "$OUT/log.txt" 2>&1
$PY benchmarks/nca_quality.py --model "$OUT/nca/model.safetensors" --exemplar-name stripes --out "$OUT/nca_quality.json" \
  > "$OUT/nca_quality.txt" 2>&1 || true
rm -rf "$W"
log "done"
tail -n 3 "$OUT/render_device.txt" "$OUT"/gan_step_*.txt "$OUT/curve.txt" "$OUT/nca/metrics.jsonl" "$OUT/nca_quality.txt"
