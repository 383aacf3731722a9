"""The Never Stop Learning study as one resumable command (``nsl study run|status|report``).

A wiring layer like the CLI: it imports the five folders, and they never import it.

    load_plan, Plan                      # plan.py: the TOML plan, validated up front
    build_units, unit_graph, Unit        # units.py: collect / train / eval units and their DAG
    run_graph                            # scheduler.py: local processes, skip finished units, status.json
    run_study, study_status, write_study_report, study_dir   # driver.py: the three subcommands
    estimate_study                       # estimate.py: minutes on this machine, from measured unit costs
"""

from .driver import estimate_study, run_study, status_lines, study_dir, study_status, write_study_report
from .plan import SHIPPED, Plan, load_plan
from .scheduler import run_graph
from .units import Unit, build_units, unit_graph

__all__ = ["SHIPPED", "estimate_study", "Plan", "Unit", "build_units", "load_plan", "run_graph", "run_study", "status_lines",
           "study_dir", "study_status", "unit_graph", "write_study_report"]
