"""Official MyoChallenge metrics of trained policies (see myo_sds/cli/evaluate.py).

    python evaluate.py runs/quickstart --env p1 --official
"""

import sys

try:
    from myo_sds.cli import exit_unless_installed, sigint_held  # the standard library only

    exit_unless_installed(__file__)  # one line saying which Python to use, instead of a traceback
    with sigint_held():  # a Ctrl-C inside an import can be lost; this one acts after it
        from myo_sds.cli.evaluate import main
except KeyboardInterrupt:  # Ctrl-C while Python starts: nothing began
    sys.exit(130)

if __name__ == "__main__":
    sys.exit(main())
