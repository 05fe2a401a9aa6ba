from roarmctl.launch import main

main()
