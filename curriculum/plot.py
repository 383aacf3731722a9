"""A picture of the optimal and pessimal curricula (PNG): trees drawn from scratch downwards, edges labelled A."""

from __future__ import annotations

from pathlib import Path

from nsl.workspace import atomic_write_bytes

from .matrix import SCRATCH
from .tree import Curriculum, Tree

DPI = 150


def _layout(tree: Tree, tasks: tuple[str, ...]) -> dict[str, tuple[float, float]]:
    """Depth on y (scratch at the top), leaves spread evenly on x, parents centred over their children."""
    children: dict[str, list[str]] = {}
    for t in tree.order(tasks):
        children.setdefault(tree.parent[t], []).append(t)
    pos: dict[str, tuple[float, float]] = {}
    next_x = [0.0]

    def place(v: str, depth: int) -> float:
        kids = children.get(v, [])
        if not kids:
            x = next_x[0]
            next_x[0] += 1.0
        else:
            xs = [place(k, depth + 1) for k in kids]
            x = (xs[0] + xs[-1]) / 2
        pos[v] = (x, -float(depth))
        return x

    place(SCRATCH, 0)
    return pos


def _draw(ax, tree: Tree, tasks: tuple[str, ...], title: str) -> None:
    pos = _layout(tree, tasks)
    for t in tasks:
        (x0, y0), (x1, y1) = pos[tree.parent[t]], pos[t]
        ax.annotate(
            "", xy=(x1, y1 + 0.12), xytext=(x0, y0 - 0.12), arrowprops={"arrowstyle": "-|>", "color": "0.35", "lw": 1.2}
        )
        # labels nearer the child, where sibling edges have spread apart
        ax.text(
            x0 + 0.65 * (x1 - x0),
            y0 + 0.65 * (y1 - y0),
            f"A={tree.advantage[t]:.2f}",
            fontsize=7,
            ha="center",
            va="center",
            bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none"},
        )
    for v, (x, y) in pos.items():
        style = {"fc": "0.9", "ec": "0.4"} if v == SCRATCH else {"fc": "#dbe9f6", "ec": "tab:blue"}
        label = v.replace("_", "\n", 1)  # 'checkerboard_backing@0.6' on two lines, so that siblings do not overlap
        ax.text(x, y, label, fontsize=8, ha="center", va="center", bbox={"boxstyle": "round,pad=0.3", **style})
    xs = [p[0] for p in pos.values()]
    ys = [p[1] for p in pos.values()]
    ax.set_xlim(min(xs) - 0.8, max(xs) + 0.8)
    ax.set_ylim(min(ys) - 0.5, max(ys) + 0.5)
    ax.set_title(f"{title}: predicted cost {tree.cost:+.2f}", fontsize=9)
    ax.axis("off")


def plot_curriculum(curriculum: Curriculum, path: str | Path) -> Path:
    """Write the optimal (left) and pessimal (right) trees side by side as a PNG; returns the path."""
    import io

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    n = len(curriculum.tasks)
    fig = Figure(figsize=(max(6.0, 1.6 * n + 2), 1.2 * n + 1.5))  # its own Agg canvas: pyplot's backend untouched
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 2)
    _draw(axes[0], curriculum.optimal, curriculum.tasks, "optimal")
    _draw(axes[1], curriculum.pessimal, curriculum.tasks, "pessimal")
    fig.suptitle("Curriculum: learn each task from its parent (C = -A)", fontsize=10)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, buf.getvalue())
    return path
