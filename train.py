"""Train a recurrent PPO policy through a YAML curriculum (see myo_sds/cli/train.py).

    python train.py --config configs/quickstart.yaml
    python train.py --resume RUN_DIR
"""

import sys

try:
    from myo_sds.cli import exit_unless_installed, sigint_held  # the standard library only

    exit_unless_installed(__file__)  # one line saying which Python to use, instead of a traceback
    with sigint_held():  # a Ctrl-C inside an import can be lost; this one acts after it
        from myo_sds.cli.train import main
except KeyboardInterrupt:  # Ctrl-C while Python starts: nothing began
    sys.exit(130)

if __name__ == "__main__":
    sys.exit(main())
