// Run Python under the 32-bit MicroPython webassembly port, as `micropython` runs it on the unix port.
//
// usage: node run_micropython.mjs [--heapsize BYTES] [--copy HOST=FS]... [--path FS]...
//                                 [--step CODE]... [--heap-report] SCRIPT [ARG...]
//
// --copy puts a host file or folder (recursively, .py/.mpy/.json/.jsonl) into the port's in-memory
// filesystem; --path goes in front of sys.path; SCRIPT (a path in that filesystem) runs as
// __main__ with sys.argv = [SCRIPT, ARG...]; each --step then runs as its own top-level exec
// in the same interpreter.  This port collects garbage only between top-level execs (its C
// stack cannot be scanned from inside wasm), growing the heap instead, so --heap-report prints
// a last line `wasm-heap: total T used U` (T: the heap's size after the run, U: in use after a
// collection): T == --heapsize means the run never needed more than that, even without a GC.
// Exit status: SystemExit's code, 1 on any other exception.
import fs from "node:fs";
import path from "node:path";
import { loadMicroPython } from "@micropython/micropython-webassembly-pyscript";

const KEEP = /\.(py|mpy|json|jsonl)$/;

function parseArgs(argv) {
  const opts = { heapsize: 1024 * 1024, copies: [], paths: [], steps: [], heapReport: false, script: null, args: [] };
  for (let i = 0; i < argv.length; i++) {
    const a = argv[i];
    if (opts.script !== null) opts.args.push(a);
    else if (a === "--heapsize") opts.heapsize = parseInt(argv[++i], 10);
    else if (a === "--copy") opts.copies.push(argv[++i].split("="));
    else if (a === "--path") opts.paths.push(argv[++i]);
    else if (a === "--step") opts.steps.push(argv[++i]);
    else if (a === "--heap-report") opts.heapReport = true;
    else opts.script = a;
  }
  if (opts.script === null || !(opts.heapsize > 0)) {
    process.stderr.write("usage: node run_micropython.mjs [--heapsize BYTES] [--copy HOST=FS]... SCRIPT [ARG...]\n");
    process.exit(2);
  }
  return opts;
}

function mkdirs(FS, dir) {
  let at = "";
  for (const part of dir.split("/").filter(Boolean)) {
    at += "/" + part;
    if (!FS.analyzePath(at).exists) FS.mkdir(at);
  }
}

function copyIn(FS, host, dest) {
  const st = fs.statSync(host);
  if (st.isDirectory()) {
    mkdirs(FS, dest);
    for (const name of fs.readdirSync(host)) {
      if (name === "node_modules" || name === "__pycache__" || name.startsWith(".")) continue;
      const sub = path.join(host, name);
      if (fs.statSync(sub).isDirectory() || KEEP.test(name)) copyIn(FS, sub, dest + "/" + name);
    }
  } else {
    mkdirs(FS, path.posix.dirname(dest));
    FS.writeFile(dest, fs.readFileSync(host));
  }
}

// SystemExit's code from the port's PythonError text; null for any other exception.
function exitCode(err) {
  const m = /SystemExit: ?(.*)\s*$/.exec(String(err.message ?? err));
  if (!m) return null;
  const code = m[1].trim();
  return code === "" || code === "None" ? 0 : /^-?\d+$/.test(code) ? parseInt(code, 10) : 1;
}

const opts = parseArgs(process.argv.slice(2));
let capture = null;
const mp = await loadMicroPython({
  heapsize: opts.heapsize,
  linebuffer: false,
  stdout: (bytes) => (capture !== null ? capture.push(Buffer.from(bytes)) : process.stdout.write(bytes)),
  stderr: (bytes) => process.stderr.write(bytes),
});
for (const [host, dest] of opts.copies) copyIn(mp.FS, host, dest);
const setup = [
  "import sys, gc",
  `sys.path[:0] = ${JSON.stringify(opts.paths)}`,
  `sys.argv[:] = ${JSON.stringify([opts.script, ...opts.args])}`,
  "gc.collect()",  // asks for a collection: it runs at the start of the next exec
].join("\n");
const script = mp.FS.readFile(opts.script, { encoding: "utf8" });
let status = 0;
try {
  mp.runPython(setup);
  mp.runPython(script);
  for (const step of opts.steps) {
    mp.runPython("gc.collect()");
    mp.runPython(step);
  }
  if (opts.heapReport) {
    mp.runPython("gc.collect()");
    mp.runPython("gc.collect()");  // runs at entry: the heap now holds only what is alive
    capture = [];
    mp.runPython("import micropython\nmicropython.mem_info()");
    const info = Buffer.concat(capture).toString();
    capture = null;
    const m = /GC: total: (\d+), used: (\d+)/.exec(info);
    process.stdout.write(`wasm-heap: total ${m ? m[1] : "?"} used ${m ? m[2] : "?"}\n`);
  }
} catch (err) {
  capture = null;
  const code = exitCode(err);
  if (code === null) {
    process.stderr.write(String(err.message ?? err) + "\n");
    status = 1;
  } else {
    status = code;
  }
}
process.exitCode = status;
