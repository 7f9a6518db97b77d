from bagtools.cli import main

main()
