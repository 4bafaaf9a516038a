// tests/wasi-run.mjs - runs a test program built for wasm32-wasi under Node's WASI,
// with the current folder as the program's file system (tests read tests/fixtures
// and write tests/out, relative to the repository root).
//   node tests/wasi-run.mjs build/wasm/t_image.wasm [args...]
// The environment passes through (APPM_TEST_QUICK and friends); the exit status
// is the program's.
import { WASI } from 'node:wasi';
import { readFile } from 'node:fs/promises';
import process from 'node:process';

const [file, ...args] = process.argv.slice(2);
const wasi = new WASI({ version: 'preview1', args: [file, ...args], env: process.env,
                        preopens: { '.': '.' }, returnOnExit: true });
const module = await WebAssembly.compile(await readFile(file));
const instance = await WebAssembly.instantiate(module, { wasi_snapshot_preview1: wasi.wasiImport });
process.exitCode = wasi.start(instance);
