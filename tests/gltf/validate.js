// Validate one .gltf or .glb file with the Khronos glTF validator; print its report as JSON.
// Used by tests/unit/export/test_gltf.py (npm install in this folder first).
const fs = require("fs");
const validator = require("gltf-validator");

const path = process.argv[2];
// The container by the file's suffix, as a viewer picks it: a .glb is read as the binary one.
const format = path.toLowerCase().endsWith(".glb") ? "glb" : "gltf";
validator
  .validateBytes(new Uint8Array(fs.readFileSync(path)), { uri: path, format })
  .then((report) => { console.log(JSON.stringify(report)); })
  .catch((err) => { console.error(String(err)); process.exit(2); });
