"""``python -m roarmctl``: the same as the ``roarmctl`` command."""

from roarmctl.launch import main

main()
