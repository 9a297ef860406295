"""One module per ``ectskin`` subcommand; each exposes ``HELP``, ``add_arguments`` and ``run``.

The modules are thin wrappers over the library: everything a command does is available from the
Python API too.
"""

#: (command name, module name) in the order ``ectskin --help`` lists them.
COMMANDS = (
    ("simulate", "simulate"),
    ("characterize", "characterize"),
    ("train", "train"),
    ("evaluate", "evaluate"),
    ("reproduce", "reproduce"),
    ("demo", "demo"),
    ("record", "record"),
    ("live", "live"),
    ("import", "import_"),
    ("design", "design"),
    ("variability", "variability"),
    ("bound", "bound"),
    ("study", "study"),
)
