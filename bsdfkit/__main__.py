from bsdfkit.cli.main import exit_process, main

if __name__ == "__main__":  # not in a helper process spawned by this one (it imports this module as __mp_main__)
    exit_process(main())
