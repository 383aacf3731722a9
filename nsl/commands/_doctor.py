"""``python -m nsl.commands._doctor``: check that this machine can run nsl (run by ``make install``)."""

from __future__ import annotations

import sys


def main() -> int:
    from nsl.errors import NslError

    try:
        from nsl.collectors.render import SceneRenderer, ensure_gl_backend

        backend = ensure_gl_backend()
        SceneRenderer(64, 64).close()
    except NslError as e:
        print(f"nsl doctor: {e}", file=sys.stderr)
        return 1
    print(f"nsl doctor: headless rendering works (MUJOCO_GL={backend})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
