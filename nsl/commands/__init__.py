"""One module per user action; each defines ``register(subparsers)``.

The CLI discovers every module in this package, so adding a command means
adding a module here and nothing else.  Command functions are short glue:
they parse references and call one folder's public surface.
"""
