"""oclgi's own fuzzing: generated inputs for every file format and command.

* :mod:`fuzz.strategies`: hypothesis strategies, one per format, each
  drawing a :class:`fuzz.oracle.Case` (the files of a case folder and the
  command line, or a scene dict for ``oclgi.load_dict``);
* :mod:`fuzz.oracle`: runs a case and judges it: exit 0 with complete,
  readable outputs, or exit 2 with one ``oclgi: error:`` line and nothing
  written; anything else is a failure of a named kind;
* :mod:`fuzz.worker`: the process that runs cases in-process, so that a
  crash or a hang costs a restart, not the test run.

``tests/test_fuzz.py`` runs a small, derandomized sample of every format;
``bench/fuzz.py`` runs the long campaign.
"""
