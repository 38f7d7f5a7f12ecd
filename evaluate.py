"""Official MyoChallenge metrics of trained policies (see myo_sds/cli/evaluate.py).

    python evaluate.py runs/quickstart --env p1 --official
"""

import sys

if __name__ == "__main__":
    try:
        from myo_sds.cli.evaluate import main
    except KeyboardInterrupt:  # Ctrl-C while Python starts: nothing began
        sys.exit(130)
    sys.exit(main())
