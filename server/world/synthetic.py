"""A synthetic data directory laid out like the real one: tests, benches and ``ttes server --synthetic``."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass
class SyntheticDataDir:
    path: Path
    startup_script: str
    soldiers: list[str] = field(default_factory=list)


def write_synthetic_data_dir(
    directory: str | Path, *, soldiers: int = 10, ndof: int = 50, amplitude: float = 0.2, seed: int = 7
) -> SyntheticDataDir:
    """A data dir laid out like the real one, with :mod:`server.soldier.synthetic`'s motion library:
    ``figures/DI.fig`` (a chain soldier) and ``figures/AK_47.fig``, ``posture_graphs/*.graph`` with their
    channelsets, ``jack-ttes-soldier_low.env`` (``soldiers`` soldier/gun pairs) and the seed's start-up script
    ``jack-ttes-soldier_low.jcl``."""
    from peabody.writer import write_figure
    from server.soldier.synthetic import synthetic_figures, write_synthetic_library

    out = Path(directory)
    (out / "figures").mkdir(parents=True, exist_ok=True)
    figs = synthetic_figures(ndof)
    for fig in figs:
        write_figure(fig, out / "figures" / (fig.filename or f"{fig.name}.fig"))
    write_synthetic_library(out / "posture_graphs", figs, amplitude=amplitude, seed=seed)
    names = [f"s{i}" for i in range(soldiers)]
    env = [
        f'figure Di2_{i} {{ file = "DI.fig"; }}\nfigure AK_47_{i} {{ file = "AK_47.fig"; }}\n'
        for i in range(soldiers)
    ]
    (out / "jack-ttes-soldier_low.env").write_text("".join(env) or "\n", encoding="utf-8")
    (out / "jack-ttes-soldier_low.jcl").write_text(startup_jcl(soldiers), encoding="utf-8")
    return SyntheticDataDir(out, "jack-ttes-soldier_low.jcl", names)


def startup_jcl(soldiers: int) -> str:
    """``jack-ttes-soldier_low.jcl`` (seed 002, 3.6) for ``soldiers`` soldiers ``Di2_i`` + ``AK_47_i`` of
    ``jack-ttes-soldier_low.env``: the shipped library's script (written by ``ttes author build``) and the
    synthetic data dir's. Our channelsets are recorded facing -Z, so the three heading offsets (posture,
    walking, crawling channelsets) are 0 where the seed's had 256."""
    lines = ['read_file("jack-ttes-soldier_low.env");']
    lines += [f'create_soldier_state("s{i}","Di2_{i}","AK_47_{i}");' for i in range(soldiers)]
    lines += [
        'set_channelset_parameters("no");',
        "set_ttes_report_interval(10.00);",
        "set_ttes_heading_offset(0.00,0.00,0.00);",
        "set_ttes_soldier_throttle(0.04);",
        "set_ttes_report_interval(30.00);",
        "start_ttes_socket_simulation();",
        "disable_graphics();",
    ]
    return "\n".join(lines) + "\n"
