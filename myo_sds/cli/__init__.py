"""The command lines (``train.py``, ``evaluate.py``; installed: ``myo-sds-train``,
``myo-sds-evaluate``). Each ``main`` sets the process environment first
(:func:`myo_sds.set_process_environment`), before NumPy, torch and MuJoCo load: the modules
import only the standard library at their top, the rest inside ``main``."""
