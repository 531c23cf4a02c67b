"""`python -m reeve_fmu.hil controller|bench ...`: the controller process and the bench on a real CAN interface."""
import sys

from .cli import main

sys.exit(main())
