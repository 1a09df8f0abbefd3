// The Khronos glTF validator on every file named: one JSON report per file on stdout.
const fs = require("fs");
const validator = require("gltf-validator");

(async () => {
  const out = {};
  for (const file of process.argv.slice(2)) {
    const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
      uri: file,
      maxIssues: 100,
    });
    out[file] = report.issues;
  }
  process.stdout.write(JSON.stringify(out));
})().catch((err) => {
  console.error(String(err));
  process.exit(2);
});
