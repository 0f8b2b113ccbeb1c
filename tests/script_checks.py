"""What the Python test scripts under tests/ share (tests/data/robomimic_h5py_test.py,
tests/report/report_test.py): a check that records a failed condition and goes on, and the
scripts' exit status. A script in a subfolder puts tests/ on sys.path to import it."""
import sys

failures = []


def check(cond, message):
    """Records `message` as a failure (and prints it) unless `cond`; returns `cond`."""
    if not cond:
        failures.append(message)
        print("FAIL: " + message, file=sys.stderr)
    return cond


def exit_status(passed_message):
    """1 after printing how many checks failed, else 0 after printing `passed_message`."""
    if failures:
        print("%d check(s) failed" % len(failures), file=sys.stderr)
        return 1
    print(passed_message)
    return 0
