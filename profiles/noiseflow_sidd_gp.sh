#!/bin/sh
# Rebuild profiles/noiseflow_sidd_gp.onnx (+ .loglik.onnx), simcam's default Noise Flow:
# a paper-configuration flow (per-ISO beta1/beta2, per-ISO/camera gain) trained by simcam on
# pairs synthesised from the measured SIDD Google Pixel NLF (profiles/sidd_pixel_nlf.csv,
# ISO 100-1600), 1000 32x32 packed patches per ISO, 8 epochs, seed 0, one thread.
# Usage (from the repository root): sh profiles/noiseflow_sidd_gp.sh [WORKDIR]
set -e
work=${1:-/tmp/simcam_noiseflow_sidd_gp}
mkdir -p "$work"
python -m simcam flow synth-nlf profiles/sidd_pixel_nlf.csv --out "$work/gp.npz" \
    --n-per 1000 --cameras GP --isos 100,400,800,1600 --seed 0
python -m simcam flow train "$work/gp.npz" --out "$work/run" --epochs 8 --seed 0 --threads 1 \
    --reference-nlf profiles/sidd_pixel_nlf.csv
python -m simcam flow export "$work/run/best.pt" --out profiles/noiseflow_sidd_gp.onnx
