// Soldiers drawn from the wire (docs/PROTOCOL.md §7.2 "Drawing"): the FIGURE rows become three.js groups
// parented as the segment tree; a pose (§8) sets the joint products D(s) and the figure roots F; the entity's
// heading and position set E (§10). Axes are the wire's: metres, +Z up. The meshes are drawn instanced
// (Crowd): one draw per segment of a figure set for all its soldiers, each soldier's segment world matrices
// written into the instance buffers when he moved, so a thousand soldiers are ~20 draws, not 20,000. A
// soldier's body takes his colour (his force's: SoldierFigure.colour) as an instance colour; rifles keep theirs.
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
  constructor(set) {
    this.set = set;
    this.entity = new THREE.Group();
    this.entity.matrixAutoUpdate = false;
    this.roots = []; this.nodes = [];
    this.colour = new THREE.Color(0xffffff); // the body's colour (times the body material's): set by the page
    for (const f of set.figures) {
      const root = new THREE.Group();
      root.matrixAutoUpdate = false;
      this.entity.add(root);
      const groups = f.segments.map(() => { const g = new THREE.Group(); g.matrixAutoUpdate = false; return g; });
      f.segments.forEach((s, k) => {
        (s.parent < 0 ? root : groups[s.parent]).add(groups[k]);
        if (s.entry < 0) groups[k].matrix.copy(s.pre).multiply(s.post); // fixed: pre · post (row 0: post = I)
      });
      this.roots.push(root);
      this.nodes.push(groups);
    }
  }

  // E from the entity's compass heading (degrees) and position: local +Y → (sin h, cos h, 0)
  place(heading, position) {
    const h = THREE.MathUtils.degToRad(heading);
    this.entity.matrix.makeRotationZ(-h).setPosition(position[0], position[1], position[2]);
    this.changed = true;
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
    this.changed = true;
  }
}

// every soldier of every figure set, drawn with one InstancedMesh per segment that has a surface
export class Crowd {
  constructor(scene, materials) {
    this.scene = scene; this.materials = materials;
    this.batches = new Map(); // FigureSet -> {parts: [{fi, k, mesh}], soldiers: [SoldierFigure]}
  }

  // forget every soldier (a new connection: new tables, new figures)
  clear() {
    for (const b of this.batches.values()) for (const p of b.parts) { this.scene.remove(p.mesh); p.mesh.dispose(); }
    this.batches.clear();
  }

  add(figure) {
    let b = this.batches.get(figure.set);
    if (!b) { b = { parts: [], soldiers: [], capacity: 0 }; this.batches.set(figure.set, b); }
    figure.slot = b.soldiers.length;
    b.soldiers.push(figure);
    if (b.soldiers.length > b.capacity) this._grow(figure.set, b, Math.max(64, 2 * b.soldiers.length));
    figure.changed = true;
  }

  _grow(set, b, capacity) {
    for (const p of b.parts) { this.scene.remove(p.mesh); p.mesh.dispose(); }
    b.parts = []; b.capacity = capacity;
    set.figures.forEach((f, fi) => f.geometry.forEach((geometry, k) => {
      const mesh = new THREE.InstancedMesh(geometry, f.name === "soldier" ? this.materials.soldier : this.materials.rifle, capacity);
      mesh.frustumCulled = false; // the instances span the village: no one bounding sphere
      mesh.count = 0;
      this.scene.add(mesh);
      b.parts.push({ fi, k, mesh, body: f.name === "soldier" });
    }));
    for (const s of b.soldiers) s.changed = true;
  }

  // write the matrices of the soldiers that moved or were posed since the last frame
  update() {
    for (const b of this.batches.values()) {
      let dirty = false;
      for (const s of b.soldiers) {
        if (!s.changed) continue;
        s.entity.updateMatrixWorld(true);
        for (const p of b.parts) {
          p.mesh.setMatrixAt(s.slot, s.nodes[p.fi][p.k].matrixWorld);
          if (p.body) p.mesh.setColorAt(s.slot, s.colour);
        }
        s.changed = false; dirty = true;
      }
      for (const p of b.parts) {
        p.mesh.count = b.soldiers.length;
        if (dirty) p.mesh.instanceMatrix.needsUpdate = true;
        if (dirty && p.mesh.instanceColor) p.mesh.instanceColor.needsUpdate = true;
      }
    }
  }

  // the world box of one soldier's surfaces
  box(s, out) {
    out.makeEmpty();
    const b = this.batches.get(s.set), part = new THREE.Box3();
    for (const p of b ? b.parts : []) {
      if (!p.mesh.geometry.boundingBox) p.mesh.geometry.computeBoundingBox();
      out.union(part.copy(p.mesh.geometry.boundingBox).applyMatrix4(s.nodes[p.fi][p.k].matrixWorld));
    }
    return out;
  }
}
