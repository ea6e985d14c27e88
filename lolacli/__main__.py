from lolacli.cli.main import main

main()
