"""Test cases and suites in memory and on disk, and the one atomic file writer.

:class:`TestCase` / :class:`TestSuite` (:mod:`reachconf.io.cases`) hold measured
test cases ⟨U, Y, T⟩ (source report section 3.1); :func:`load_suite` /
:func:`save_suite` (:mod:`reachconf.io.files`) read and write folders of CSV or
NPZ files; :func:`atomic_write` (:mod:`reachconf.io.atomic`) is how every file
of the package is written, :func:`json_text` (:mod:`reachconf.io.jsonfile`) how
every JSON result is serialised (strict: no NaN/Infinity), and
:class:`RunOutputs` (:mod:`reachconf.io.output`) how a command checks and locks
its output paths before the work.
"""

from reachconf.io.atomic import atomic_write, atomic_write_text, write_new
from reachconf.io.cases import TestCase, TestSuite, case_arrays, check_signals
from reachconf.io.files import UNITS, load_case, load_suite, save_case, save_suite
from reachconf.io.jsonfile import json_text, to_jsonable
from reachconf.io.output import OutputLock, RunOutputs, check_output_file, check_output_folder
from reachconf.io.results import JsonResult, read_json

__all__ = ["TestCase", "TestSuite", "load_suite", "save_suite", "load_case", "save_case", "UNITS", "atomic_write",
           "atomic_write_text", "write_new", "check_signals", "case_arrays", "json_text", "to_jsonable", "OutputLock",
           "RunOutputs", "check_output_file", "check_output_folder", "JsonResult", "read_json"]  # fmt: skip
