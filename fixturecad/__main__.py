from fixturecad.cli import main

main()
