"""``nsl push REF DEST`` and ``nsl pull SRC``: share dataset versions and checkpoints, hash-verified.

The transfer (manifests, skipping, verification, resuming) is ``nsl.share``;
``nsl.push`` and ``nsl.pull`` (``nsl.services.share``) resolve references,
write the cards, and register what a pull brings in with its origin.  These
commands parse and print.
"""

from __future__ import annotations

import argparse

REMOTES = """\
remotes:
  hf://datasets/OWNER/NAME   a Hugging Face dataset repo (LeRobot layout, tags vN and v3.0)
  hf://OWNER/NAME            a Hugging Face model repo (model.safetensors, config.json, card)
  s3://bucket/prefix         any fsspec URL (gs://, az://, file:///path) or a plain folder path
  SRC@REV                    pull a revision: @v2 (a dataset version), a Hub branch or commit

credentials: HF_TOKEN or `hf auth login` for the Hub; fsspec's own configuration (e.g. AWS_PROFILE)
for cloud stores.  nsl never prints or records a token.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "push",
        help="publish a dataset version or a checkpoint to the Hub or an fsspec remote",
        description="Upload a dataset version (data:NAME@vN) or a checkpoint (ckpt:NAME@STEP, "
        "@best, @TAG) with a manifest of sha256 digests and a card. Files the remote "
        "already holds with the same digest are not sent again.",
        epilog=REMOTES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("ref", help="data:NAME@vN or ckpt:NAME[@STEP|@best|@TAG]")
    p.add_argument("dest", help="hf://datasets/OWNER/NAME, hf://OWNER/NAME, s3://bucket/prefix, file:///path, ...")
    p.set_defaults(func=run_push)

    q = sub.add_parser(
        "pull",
        help="bring a shared dataset version or checkpoint into the workspace",
        description="Download a dataset version or checkpoint, check every file against the "
        "published sha256 digests, then move it into the workspace and register it "
        "in the catalog with its origin (URL and revision). An interrupted pull "
        "resumes, skipping the files it already verified.",
        epilog=REMOTES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    q.add_argument("src", help="remote, optionally with @REVISION (e.g. hf://datasets/lab/grasp-harsh@v2)")
    q.add_argument(
        "--as",
        dest="as_name",
        metavar="NAME",
        default=None,
        help="local dataset or checkpoint name (default: the published one)",
    )
    q.set_defaults(func=run_pull)


# ------------------------------------------------------------------- push
def run_push(args: argparse.Namespace) -> int:
    import nsl

    result = nsl.push(args.ref, args.dest)
    tags = f", tags {', '.join(result.tags)}" if result.tags else ""
    sent = f"uploaded {len(result.uploaded)} file(s)" if result.uploaded else "uploaded nothing (already there)"
    print(
        f"pushed {result.what} to {result.url} (revision {result.revision}{tags}): {sent}, "
        f"{len(result.unchanged)} unchanged"
    )
    return 0


# ------------------------------------------------------------------- pull
def run_pull(args: argparse.Namespace) -> int:
    import nsl

    result = nsl.pull(args.src, as_name=args.as_name)
    print(
        f"pulled {result.url} (revision {result.revision}) as {result.what}: {len(result.downloaded)} file(s) "
        f"downloaded, {len(result.reused)} already verified"
    )
    return 0
