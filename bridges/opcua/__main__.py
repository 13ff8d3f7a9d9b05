from landscape.bridges.opcua.server import main

main()
