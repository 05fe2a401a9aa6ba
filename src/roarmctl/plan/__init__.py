"""Plan files: the schema (every field checked, errors naming the file, line and field), the ``Plan`` a file
becomes, and the writer (``writer``: a plan as YAML text, as ``teach`` saves one). The YAML itself is read by
``roarmctl.validation``; tasks become motions in
``roarmctl.motion.planning.tasks``."""
