from landscape.bridges.foxglove.server import main

main()
