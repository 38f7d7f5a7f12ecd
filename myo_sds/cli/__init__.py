"""The command lines (``train.py``, ``evaluate.py``; installed: ``myo-sds-train``,
``myo-sds-evaluate``). Importing them is running an entry point: the process environment is set
here, before NumPy, torch and MuJoCo load."""

from myo_sds import set_process_environment

set_process_environment()
