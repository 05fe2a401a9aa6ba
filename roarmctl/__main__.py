from roarmctl.cli import main

main()
