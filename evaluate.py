"""Official MyoChallenge metrics of trained policies (see myo_sds/cli/evaluate.py).

    python evaluate.py runs/quickstart --env p1 --official
"""

import sys

from myo_sds.cli.evaluate import main

if __name__ == "__main__":
    sys.exit(main())
