// Decodes an .spz with Niantic's own library (@adobe/spz: its C++ built to WebAssembly), asking
// for RDF axes (the PLY's), and prints the Gaussian cloud as JSON: the independent reader
// behind tests/tests/spz_niantic.rs.
import { readFileSync } from "node:fs";
import createSpzModule from "@adobe/spz";

// The library logs to stdout; keep that for the JSON.
const spz = await createSpzModule({ print: (s) => process.stderr.write(`${s}\n`) });
const bytes = new Uint8Array(readFileSync(process.argv[2]));
const cloud = spz.loadSpzFromBuffer(bytes, { to: spz.CoordinateSystem.RDF });
const out = {
  numPoints: cloud.numPoints,
  shDegree: cloud.shDegree,
  antialiased: cloud.antialiased,
};
for (const key of ["positions", "scales", "rotations", "alphas", "colors", "sh"]) {
  out[key] = Array.from(cloud[key]);
}
process.stdout.write(JSON.stringify(out));
