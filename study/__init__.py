"""The Never Stop Learning study as one resumable command (``nsl study run|status|report``), and transfer.

A wiring layer like the CLI: it imports the five folders, and they never import it.

    load_plan, Plan                      # plan.py: the TOML plan, validated up front
    build_units, unit_graph, Unit        # units.py: collect / train / eval units and their DAG
    run_graph                            # scheduler.py: local processes, skip finished units, status.json
    run_study, study_status, write_study_report, study_dir   # driver.py: the three subcommands
    estimate_study                       # estimate.py: minutes on this machine, from measured unit costs
    load_transfer_plan, TransferPlan     # transfer.py: a transfer plan and its fine-tune/scratch units
    run_transfer, transfer_status, write_transfer_report, estimate_transfer, transfer_dir   # transfer_run.py
    run_curricula                        # curricula.py + transfer_run.py: follow the curricula for real
    suggest_base                         # proxy.py: rank checkpoints for a new task (measured, else offline proxy)
"""

from .driver import (
    cluster_slots,
    estimate_study,
    run_study,
    status_lines,
    study_dir,
    study_status,
    write_study_report,
)
from .plan import SHIPPED, Plan, load_plan
from .proxy import suggest_base
from .scheduler import run_graph
from .transfer import SHIPPED_TRANSFER, TransferPlan, load_transfer_plan
from .transfer_run import (
    estimate_transfer,
    run_curricula,
    run_transfer,
    transfer_dir,
    transfer_status,
    write_transfer_report,
)
from .units import Unit, build_units, unit_graph

__all__ = [
    "SHIPPED",
    "SHIPPED_TRANSFER",
    "cluster_slots",
    "estimate_study",
    "estimate_transfer",
    "Plan",
    "TransferPlan",
    "Unit",
    "build_units",
    "load_plan",
    "load_transfer_plan",
    "run_curricula",
    "run_graph",
    "run_study",
    "run_transfer",
    "status_lines",
    "study_dir",
    "study_status",
    "suggest_base",
    "transfer_dir",
    "transfer_status",
    "unit_graph",
    "write_study_report",
    "write_transfer_report",
]
