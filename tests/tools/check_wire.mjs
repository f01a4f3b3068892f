// The page's wire decoder (client_stub/web/js/wire.js) over frames the Python encoder wrote: reads a JSON case
// file {version, table, payloads: [hex]} and prints every soldier's field codes after them (JSON).
import { readFileSync } from "node:fs";
import { UpdateTable, applyJointUpdates } from "../../client_stub/web/js/wire.js";

const c = JSON.parse(readFileSync(process.argv[2], "utf8"));
const table = new UpdateTable(c.table);
const tables = new Map([[table.id, table]]);
for (const hex of c.payloads) applyJointUpdates(tables, Uint8Array.from(Buffer.from(hex, "hex")), c.version);
const out = {};
for (const [i, s] of table.soldiers) out[i] = { codes: Array.from(s.cur), pose: table.pose(i) };
for (const v of Object.values(out)) v.pose.dofs = Array.from(v.pose.dofs);
console.log(JSON.stringify(out));
