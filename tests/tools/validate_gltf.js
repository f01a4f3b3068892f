// Runs the Khronos glTF validator (npm: gltf-validator) on each .glb/.gltf given; prints one JSON report per
// file on stdout (a list). NODE_PATH may point at the folder where `npm install gltf-validator` put it.
const fs = require("fs");
const validator = require("gltf-validator");

async function main(paths) {
  const reports = [];
  for (const p of paths) {
    const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(p)), { maxIssues: 100 });
    reports.push({ path: p, issues: report.issues, info: report.info });
  }
  process.stdout.write(JSON.stringify(reports));
}

main(process.argv.slice(2)).catch((e) => {
  console.error(e);
  process.exit(1);
});
