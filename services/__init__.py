"""The service layer: one module per user action, over the five folders.

The Python API (``nsl.api``, re-exported as ``nsl.collect``, ``nsl.train``, ...),
the command line, the study's units and the experiment scripts all call these
functions, so each action has one implementation::

    options        the configs of every action: the one source of their defaults (light: no torch, no MuJoCo)
    refs           references to objects: policy factories, catalogued parents, dataset registration
    collect        collect episodes into a versioned dataset and catalogue it
    train          pre-train or fine-tune, with early stopping; register the run's checkpoints
    scoring        offline scores on held-out episodes: SoftOPC, AUC, TD error
    evaluate       success rates with intervals, stored in the catalog
    compare        two methods' catalogued evaluations side by side: paired intervals, aggregates across shifts
    continual      a sequence of fine-tunes and its performance matrix
    efficiency     fine-tunes on each data tier
    share          push and pull, verified and catalogued

Layering (``tests/test_import_graph.py``): the services import the core, the
five folders, ``nsl.cluster`` and ``nsl.share``; ``nsl.study`` and the API sit
above them, and nothing here imports those or the command line.
"""
