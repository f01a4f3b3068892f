// Soldiers drawn from the wire (docs/PROTOCOL.md §7.2 "Drawing"): the FIGURE rows become three.js groups
// parented as the segment tree, each segment's mesh a child; a pose (§8) sets the joint products D(s) and the
// figure roots F; the entity's heading and position set E (§10). Axes are the wire's: metres, +Z up.
import * as THREE from "three";

const m4 = (t) => new THREE.Matrix4().set(t[0], t[1], t[2], t[3], t[4], t[5], t[6], t[7], t[8], t[9], t[10], t[11], 0, 0, 0, 1);

// one FIGURE message, prepared once per table: transforms as matrices, mesh geometries shared by all soldiers
export class FigureSet {
  constructor(msg, table) {
    this.table = table;
    this.figures = msg.figures.map((f) => ({
      name: f.name,
      slot: table.entries.findIndex((e) => e.kind === "figure" && e.name === f.name),
      segments: f.segments.map(([name, parent, entry, reverse, pre, post]) => ({ name, parent, entry, reverse, pre: m4(pre), post: m4(post) })),
      joints: new Map(f.joints.map(([entry, name, dofs]) => [entry, { name, dofs: dofs.map(([kind, ax, ay, az]) => ({ kind, axis: new THREE.Vector3(ax, ay, az) })) }])),
      geometry: new Map((f.meshes || []).map(([segment, vertices, triangles]) => {
        const g = new THREE.BufferGeometry();
        g.setAttribute("position", new THREE.Float32BufferAttribute(vertices, 3));
        g.setIndex(triangles);
        g.computeVertexNormals();
        return [segment, g];
      })),
    }));
  }
}

const _d = new THREE.Matrix4(), _m = new THREE.Matrix4();

// D(s): the product of the joint's DOF motions (reversed joints: the inverse product)
function jointMatrix(joint, dofs, column, reverse, out) {
  out.identity();
  const n = joint.dofs.length;
  for (let k = 0; k < n; k++) {
    const i = reverse ? n - 1 - k : k;
    const q = reverse ? -dofs[column + i] : dofs[column + i];
    const d = joint.dofs[i];
    if (d.kind === "R") _m.makeRotationAxis(d.axis, q);
    else _m.makeTranslation(d.axis.x * q, d.axis.y * q, d.axis.z * q);
    out.multiply(_m);
  }
  return out;
}

export class SoldierFigure {
  constructor(set, materials) {
    this.set = set;
    this.entity = new THREE.Group();
    this.entity.matrixAutoUpdate = false;
    this.roots = []; this.nodes = [];
    for (const f of set.figures) {
      const root = new THREE.Group();
      root.matrixAutoUpdate = false;
      this.entity.add(root);
      const groups = f.segments.map(() => { const g = new THREE.Group(); g.matrixAutoUpdate = false; return g; });
      f.segments.forEach((s, k) => {
        (s.parent < 0 ? root : groups[s.parent]).add(groups[k]);
        if (s.entry < 0) groups[k].matrix.copy(s.pre).multiply(s.post); // fixed: pre · post (row 0: post = I)
        const geometry = f.geometry.get(k);
        if (geometry) {
          const mesh = new THREE.Mesh(geometry, f.name === "soldier" ? materials.soldier : materials.rifle);
          mesh.matrixAutoUpdate = false;
          groups[k].add(mesh);
        }
      });
      this.roots.push(root);
      this.nodes.push(groups);
    }
  }

  // E from the entity's compass heading (degrees) and position: local +Y → (sin h, cos h, 0)
  place(heading, position) {
    const h = THREE.MathUtils.degToRad(heading);
    this.entity.matrix.makeRotationZ(-h).setPosition(position[0], position[1], position[2]);
    this.entity.matrixWorldNeedsUpdate = true;
  }

  // a decoded pose ({dofs, figures}, wire.UpdateTable.pose): F per figure, D(s) per moving segment
  pose(p) {
    const t = this.set.table;
    this.set.figures.forEach((f, i) => {
      const fp = p.figures[t.figureSlot[f.slot]];
      if (fp) {
        const [w, x, y, z] = fp.quaternion;
        this.roots[i].matrix.makeRotationFromQuaternion(new THREE.Quaternion(x, y, z, w)).setPosition(...fp.position);
      }
      f.segments.forEach((s, k) => {
        if (s.entry < 0) return;
        const joint = f.joints.get(s.entry);
        jointMatrix(joint, p.dofs, t.dofColumn[s.entry], s.reverse, _d);
        this.nodes[i][k].matrix.copy(s.pre).multiply(_d).multiply(s.post);
      });
    });
    this.entity.matrixWorldNeedsUpdate = true;
  }
}
