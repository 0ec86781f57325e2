"""The sub-commands of the ``rtseg`` console command, one module each (``live``, ``demo``,
``segment``, ``evaluate``, ``learn``, ``plot``, ``simulate``): each adds its arguments to
the parser (``add_parser``), runs (``run``) and prints.  They hold argument parsing and
printing only; the work is in ``rtseg.live``, ``rtseg.evaluation``, ``rtseg.archive``,
``rtseg.detectors`` and ``rtseg.identity``.  Nothing outside ``rtseg.commands`` and
``rtseg.cli`` imports them (tests/test_import_graph.py).

May import any package of rtseg, ``rtseg.drivers`` and ``rtseg.simulators``."""
