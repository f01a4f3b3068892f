"""`ttes dis`: read DIS logfiles (pcap, pcapng, .dislog, raw PDUs) and write synthetic exercises.

TTES "filters and translates the DIS stream into a set of posture and command tokens" (seed report,
section 2): `dump` shows that translation for every Entity State PDU of a log, `info` counts what a log
holds, `synth` writes a squad exercise as a pcap to test everything downstream with.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from ttes.arguments import UsageError, count, port, positive


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("dis", help="read DIS logs and write synthetic DIS exercises", description=__doc__)
    dis = p.add_subparsers(dest="dis_command", metavar="ACTION")
    dis.required = True

    def add_reading(q: argparse.ArgumentParser) -> None:
        q.add_argument("path", help="pcap, pcapng, .dislog or raw PDU file")
        q.add_argument("--json", action="store_true", help="machine-readable output")
        q.add_argument("--port", type=port, default=3000, help="UDP port of the DIS traffic (default 3000)")
        q.add_argument("--any-port", action="store_true", help="take DIS from every UDP port")
        q.add_argument(
            "--format", default="auto", choices=("auto", "pcap", "pcapng", "dislog", "raw"), help="log format"
        )
        q.add_argument("--exercise", type=exercise_id, metavar="N",
                       help="only the PDUs of DIS exercise N (1..255; default: every exercise)")  # fmt: skip

    d = dis.add_parser(
        "dump",
        help="one line per Entity State PDU (posture, weapon, heading, ...)",
        description="Print every Entity State PDU of a log in file order (JSON lines with --json); other PDU "
        "types appear as skipped lines. A summary goes to stderr.",
    )
    add_reading(d)
    d.add_argument("--all-entities", action="store_true", help="decode non-lifeform entities too")
    d.add_argument("--events", action="store_true", help="attach the decoded event to Fire/Detonation lines")
    d.add_argument("--origin", help="LAT,LON,H of the local frame for the table (default: first entity)")
    d.set_defaults(func=run_dump)

    i = dis.add_parser(
        "info", help="counts: PDUs by type, entities, lifeforms, duration", description=__doc__
    )
    add_reading(i)
    i.set_defaults(func=run_info)

    s = dis.add_parser(
        "synth",
        help="write a synthetic squad exercise as a pcap",
        description="Soldiers patrol, run, kneel, go prone, crawl and fire; one is killed. Ethernet/IPv4/UDP "
        "broadcasts to port 3000, deterministic for a seed.",
    )
    s.add_argument("--out", required=True, help="output .pcap path")
    s.add_argument("--soldiers", type=count(1), default=8, help="number of soldiers (alternating forces)")
    s.add_argument("--seconds", type=positive, default=60.0, help="exercise length (s)")
    s.add_argument("--seed", type=int, default=0, help="random seed")
    s.add_argument("--origin", help="LAT,LON,H of the exercise (default: Quantico MOUT, 38.52,-77.44,60)")
    s.add_argument("--vehicles", type=count(0), default=1, help="parked vehicles (non-lifeform traffic)")
    s.add_argument("--dis-version", type=int, default=7, choices=(5, 6, 7), help="DIS protocol version")
    s.add_argument("--json", action="store_true", help="machine-readable summary")
    s.set_defaults(func=run_synth)


def exercise_id(text: str) -> int:
    """``--exercise N``: a DIS exercise identifier (the header's u8; 0 is not a valid exercise)."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 1 <= value <= 255:
        raise argparse.ArgumentTypeError(f"an exercise ID is 1..255, not {text!r}")
    return value


def not_dis(command: str, path: object, log: Any) -> bool:
    """Say so on stderr when ``log`` is not DIS at all (a text file, an image): the caller exits 1."""
    why = log.not_dis()
    if why is not None:
        print(f"ttes {command}: {path}: {why}", file=sys.stderr)
    return why is not None


def _origin(text: str | None) -> tuple[float, float, float] | None:
    if not text:
        return None
    try:
        vals = [float(x) for x in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) not in (2, 3):
        raise UsageError(f"--origin wants LAT,LON[,H], not {text!r}")
    return (vals[0], vals[1], vals[2] if len(vals) == 3 else 0.0)


def _progress() -> Any:
    """A tqdm progress callback when stderr is a terminal, else None."""
    if not sys.stderr.isatty():
        return None, None
    from tqdm import tqdm

    bar = tqdm(unit=" packets", file=sys.stderr, leave=False)

    def update(n: int) -> None:
        bar.update(n - bar.n)

    return update, bar


def _read(args: argparse.Namespace, lifeforms_only: bool = True) -> Any:
    from protocol.dis.logfile import read_log

    update, bar = _progress()
    try:
        return read_log(
            args.path,
            fmt=args.format,
            port=None if args.any_port else args.port,
            lifeforms_only=lifeforms_only,
            progress=update,
            exercise=args.exercise,
        )
    finally:
        if bar is not None:
            bar.close()


def _summary_line(log: Any) -> str:
    c = log.counters
    return (
        f"dis: {log.source} ({log.format}): {c.get('records', 0)} records, {c['pdus']} PDUs, "
        f"{c['lifeforms']} lifeform entity states, {c['non_lifeforms']} non-lifeform, {c['fire']} fire, "
        f"{c['detonation']} detonation, {c['other_pdus']} other, {c['non_dis']} non-DIS, "
        f"{len(log.issues)} corrupt, {log.duration:.3f} s"
    )


def _report(log: Any) -> None:
    for err in log.issues[:20]:
        print(f"dis: warning: {err}", file=sys.stderr)
    if len(log.issues) > 20:
        print(f"dis: warning: ... {len(log.issues) - 20} more", file=sys.stderr)
    print(_summary_line(log), file=sys.stderr)


def dump_rows(log: Any, attach_events: bool = False) -> list[dict[str, Any]]:
    """The JSON objects `ttes dis dump --json` prints, in file order (also used by tests)."""
    import numpy as np

    from protocol.dis.appearance import (
        HEALTH_NAMES,
        POSTURE_NAMES,
        WEAPON_NAMES,
        decode_appearance,
        ttes_posture,
    )
    from protocol.dis.appearance import TtesPosture as P
    from protocol.dis.entity_type import is_lifeform
    from protocol.dis.geo import heading_deg
    from protocol.dis.logfile import PduStatus
    from protocol.dis.pdu import PduType

    r = log.batch.records
    fields = decode_appearance(r["appearance"])
    life = is_lifeform(r["entity_type"]["kind"], r["entity_type"]["domain"])
    cols = {
        "version": r["version"].tolist(),
        "entity": r["entity_id"].tolist(),
        "force": r["force_id"].tolist(),
        "type": r["entity_type"].tolist(),
        "marking": [bytes(m).split(b"\0", 1)[0].decode("latin-1") for m in r["marking"].tolist()],
        "appearance": r["appearance"].tolist(),
        "state": fields["state"].tolist(),
        "ttes": ttes_posture(r["appearance"]).tolist(),
        "weapon1": fields["weapon1"].tolist(),
        "health": fields["health"].tolist(),
        "frozen": fields["frozen"].tolist(),
        "deactivated": fields["deactivated"].tolist(),
        "velocity": r["velocity"].astype(np.float64).tolist(),
        "location": r["location"].tolist(),
        "orientation": r["orientation"].astype(np.float64).tolist(),
        "heading": heading_deg(r["location"], r["orientation"]).tolist() if len(r) else [],
        "dr": r["dr_algorithm"].tolist(),
        "params": r["num_params"].tolist(),
        "life": life.tolist(),
        "update": (r["pdu_type"] == PduType.ENTITY_STATE_UPDATE).tolist(),
    }
    pdus = log.pdus
    t_rel = np.round(pdus["t"] - log.t0, 6).tolist()
    status, ptype, bidx = pdus["status"].tolist(), pdus["pdu_type"].tolist(), pdus["batch_index"].tolist()
    events = iter(log.events)
    rows: list[dict[str, Any]] = []
    names = {
        PduStatus.NOT_LIFEFORM: "not_lifeform",
        PduStatus.CORRUPT: "corrupt",
        PduStatus.UNSUPPORTED_VERSION: "unsupported_version",
        PduStatus.OTHER_EXERCISE: "other_exercise",
        PduStatus.NO_BASE: "update_without_entity_state",
    }
    for k, st in enumerate(status):
        if st == PduStatus.DECODED:
            i = bidx[k]
            lf = cols["life"][i]
            rows.append(
                {
                    "t": t_rel[k],
                    "version": cols["version"][i],
                    "entity": list(cols["entity"][i]),
                    "force": cols["force"][i],
                    "type": list(cols["type"][i]),
                    "marking": cols["marking"][i],
                    "appearance": cols["appearance"][i],
                    "posture": POSTURE_NAMES[cols["state"][i]] if lf else None,
                    "ttes_posture": P(cols["ttes"][i]).name if lf else None,
                    "weapon1": WEAPON_NAMES[cols["weapon1"][i]] if lf else None,
                    "health": cols["health"][i],
                    "health_name": HEALTH_NAMES[cols["health"][i]],
                    "frozen": cols["frozen"][i],
                    "deactivated": cols["deactivated"][i],
                    "velocity": cols["velocity"][i],
                    "location": cols["location"][i],
                    "orientation": cols["orientation"][i],
                    "heading_deg": round(cols["heading"][i], 6),
                    "dr_algorithm": cols["dr"][i],
                    "articulations": cols["params"][i],
                    **({"update": True} if cols["update"][i] else {}),
                }
            )
            continue
        row: dict[str, Any] = {"t": t_rel[k], "pdu_type": ptype[k], "skipped": True}
        if st in names:
            row["reason"] = names[st]
        if st == PduStatus.EVENT:
            ev = next(events)
            if attach_events:
                row["event"] = {**ev.to_json(), "t": t_rel[k]}
        rows.append(row)
    return rows


def run_dump(args: argparse.Namespace) -> int:
    from ttes.output import print_json

    log = _read(args, lifeforms_only=not args.all_entities)
    if not_dis("dis dump", args.path, log):
        return 1
    rows = dump_rows(log, attach_events=args.events)
    out = sys.stdout
    if args.json:
        for row in rows:
            print_json(row, stream=out)
    else:
        _print_table(log, rows, _origin(args.origin), out)
    _report(log)
    return 0


def _print_table(
    log: Any, rows: list[dict[str, Any]], origin: tuple[float, float, float] | None, out: Any
) -> None:
    import numpy as np

    from protocol.dis.geo import LocalFrame

    frame = LocalFrame(*origin) if origin else None
    out.write(
        f"{'t':>9} {'entity':<14} {'F':>1} {'marking':<11} {'posture':<12} {'ttes':<5} {'weapon':<8} "
        f"{'hp':>2} {'heading':>7} {'east':>9} {'north':>9} {'up':>7} {'speed':>6}\n"
    )
    for row in rows:
        if row.get("skipped"):
            reason = row.get("reason", "")
            note = f": {reason}" if reason else ""
            out.write(f"{row['t']:9.3f} (PDU type {row['pdu_type']} skipped{note})\n")
            continue
        if frame is None:
            frame = LocalFrame.at_ecef(row["location"])
        e, n, u = frame.to_local(row["location"]).tolist()
        ve, vn, _ = frame.vector_to_local(row["velocity"]).tolist()
        ent = ":".join(str(x) for x in row["entity"])
        out.write(
            f"{row['t']:9.3f} {ent:<14} {row['force']:>1} {row['marking']:<11} {row['posture'] or '-':<12} "
            f"{row['ttes_posture'] or '-':<5} {row['weapon1'] or '-':<8} {row['health']:>2} "
            f"{row['heading_deg']:7.1f} {e:9.2f} {n:9.2f} {u:7.2f} {float(np.hypot(ve, vn)):6.2f}\n"
        )


def run_info(args: argparse.Namespace) -> int:
    import numpy as np

    from protocol.dis.entity_type import is_lifeform
    from protocol.dis.pdu import pdu_type_name
    from server.logging import plain
    from ttes.output import print_json

    log = _read(args, lifeforms_only=False)
    if not_dis("dis info", args.path, log):
        return 1
    r = log.batch.records
    life = is_lifeform(r["entity_type"]["kind"], r["entity_type"]["domain"])
    info = log.summary()
    info["pdu_types"] = {pdu_type_name(int(k)): v for k, v in info["pdu_types"].items()}
    info["lifeform_entities"] = int(np.unique(r["entity_id"][life]).shape[0]) if life.any() else 0
    info["first_time"] = log.t0
    info["issue_list"] = [str(e) for e in log.issues[:100]]
    if args.json:
        print_json(info)
    else:
        for key, value in info.items():
            if key != "issue_list":
                print(f"{key:>20}: {plain(value)}")
        for e in info["issue_list"]:
            print(f"{'issue':>20}: {e}")
    return 0


def run_synth(args: argparse.Namespace) -> int:
    from protocol.dis.synth import QUANTICO_MOUT, synthesize, write_pcap
    from ttes.output import print_json

    bar = None
    update = None
    if sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(unit=" steps", file=sys.stderr, leave=False)

        def update(step: int, steps: int) -> None:
            bar.total = steps
            bar.update(step - bar.n)

    try:
        ex = synthesize(
            soldiers=args.soldiers,
            seconds=args.seconds,
            seed=args.seed,
            origin=_origin(args.origin) or QUANTICO_MOUT,
            vehicles=args.vehicles,
            version=args.dis_version,
            progress=update,
        )
    finally:
        if bar is not None:
            bar.close()
    n = write_pcap(args.out, ex)
    summary = {
        "out": args.out,
        "packets": n,
        **ex.counts,
        "soldiers": len(ex.entities),
        "victim": list(ex.entities[ex.victim]) if ex.victim is not None else None,
        "killer": list(ex.entities[ex.killer]) if ex.killer is not None else None,
        "t_kill": ex.t_kill,
        "origin": [ex.frame.lat, ex.frame.lon, ex.frame.height],
    }
    if args.json:
        print_json(summary)
    else:
        print(
            f"wrote {args.out}: {n} packets ({ex.counts['entity_state']} soldier entity states, "
            f"{ex.counts['fire']} fire, {ex.counts['detonation']} detonation, "
            f"{ex.counts['vehicle_entity_state']} vehicle), {len(ex.entities)} soldiers, "
            + (
                f"victim {':'.join(map(str, summary['victim']))} at t={ex.t_kill:.1f} s"
                if ex.victim is not None
                else "no victim"
            )
        )
    return 0
