// The page's wire code (client_stub/web/js/wire.js, its msgpack the vendored @msgpack/msgpack) over frames the
// Python encoder wrote: reads a JSON case file {version, update_table: hex, payloads: [hex]}, decodes the
// UPDATE_TABLE with the page's parseMessage and applies the JOINT_UPDATES; prints every soldier's field codes
// after them, and the HELLO frame the page would send (hex) for the Python decoder to read (JSON).
import { readFileSync } from "node:fs";
import { T, UpdateTable, applyJointUpdates, hello, parseMessage } from "../../client_stub/web/js/wire.js";

const c = JSON.parse(readFileSync(process.argv[2], "utf8"));
const hex = (h) => Uint8Array.from(Buffer.from(h, "hex"));
const table = new UpdateTable(parseMessage(T.UPDATE_TABLE, hex(c.update_table)));
const tables = new Map([[table.id, table]]);
for (const p of c.payloads) applyJointUpdates(tables, hex(p), c.version);
const out = {};
for (const [i, s] of table.soldiers) out[i] = { codes: Array.from(s.cur), pose: table.pose(i) };
for (const v of Object.values(out)) v.pose.dofs = Array.from(v.pose.dofs);
const greeting = Buffer.from(hello("ttes-web", "observer", c.version, { token: "sésame" })).toString("hex");
console.log(JSON.stringify({ soldiers: out, hello: greeting }));
