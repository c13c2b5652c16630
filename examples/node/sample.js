#!/usr/bin/env node
// Run a simcam Noise Flow sampler (model.onnx from `simcam flow export`) with
// onnxruntime-node: reads a clean packed patch and a latent from .npy files
// (float32, [B,4,H,W], channels (0,0),(0,1),(1,0),(1,1) of the 2x2 CFA cell) and
// writes the noise as .npy.
//
//   node sample.js model.onnx clean.npy z.npy ISO CAMERA_INDEX noise.npy
//
// ISO must lie inside the model's trained range (metadata_props iso_min/iso_max;
// the Python sampler checks it, this minimal example does not).
'use strict';
const fs = require('fs');
const ort = require('onnxruntime-node');

function readNpy(path) {
  const buf = fs.readFileSync(path);
  if (buf.toString('latin1', 0, 6) !== '\x93NUMPY') throw new Error(`${path}: not a .npy file`);
  const major = buf[6];
  const hlen = major === 1 ? buf.readUInt16LE(8) : buf.readUInt32LE(8);
  const start = major === 1 ? 10 : 12;
  const header = buf.toString('latin1', start, start + hlen);
  if (!/'descr':\s*'<f4'/.test(header)) throw new Error(`${path}: dtype: expected '<f4' (float32), header ${header.trim()}`);
  if (/'fortran_order':\s*True/.test(header)) throw new Error(`${path}: fortran_order: expected C order`);
  const shape = header.match(/'shape':\s*\(([^)]*)\)/)[1].split(',').filter((s) => s.trim()).map(Number);
  if (shape.length !== 4 || shape[1] !== 4) throw new Error(`${path}: shape: expected [B,4,H,W], got [${shape}]`);
  const off = start + hlen;
  const data = new Float32Array(buf.buffer.slice(buf.byteOffset + off, buf.byteOffset + buf.length));
  return { data, shape };
}

function writeNpy(path, data, shape) {
  let header = `{'descr': '<f4', 'fortran_order': False, 'shape': (${shape.join(', ')}${shape.length === 1 ? ',' : ''}), }`;
  const pad = 64 - ((10 + header.length + 1) % 64);
  header = header + ' '.repeat(pad % 64) + '\n';
  const head = Buffer.alloc(10);
  head.write('\x93NUMPY', 0, 'latin1');
  head[6] = 1; head[7] = 0;
  head.writeUInt16LE(header.length, 8);
  fs.writeFileSync(path, Buffer.concat([head, Buffer.from(header, 'latin1'), Buffer.from(data.buffer, data.byteOffset, data.byteLength)]));
}

async function main() {
  const [modelPath, cleanPath, zPath, isoArg, camArg, outPath] = process.argv.slice(2);
  if (!outPath) {
    console.error('usage: node sample.js model.onnx clean.npy z.npy ISO CAMERA_INDEX noise.npy');
    process.exit(2);
  }
  const clean = readNpy(cleanPath);
  const z = readNpy(zPath);
  if (clean.shape.join() !== z.shape.join()) throw new Error(`z: shape [${z.shape}] differs from clean [${clean.shape}]`);
  const b = clean.shape[0];
  const iso = Number(isoArg);
  const cam = BigInt(parseInt(camArg, 10));
  if (!(iso > 0)) throw new Error(`ISO: expected a positive number, got ${isoArg}`);
  const session = await ort.InferenceSession.create(modelPath, { intraOpNumThreads: 1 });
  const feeds = {
    clean: new ort.Tensor('float32', clean.data, clean.shape),
    z: new ort.Tensor('float32', z.data, z.shape),
    iso: new ort.Tensor('float32', Float32Array.from({ length: b }, () => iso), [b]),
    camera: new ort.Tensor('int64', BigInt64Array.from({ length: b }, () => cam), [b]),
  };
  const out = await session.run(feeds);
  writeNpy(outPath, out.noise.data, out.noise.dims);
  console.log(`wrote ${outPath} [${out.noise.dims}]`);
}

main().catch((err) => {
  console.error(`sample.js: error: ${err.message}`);
  process.exit(2);
});
