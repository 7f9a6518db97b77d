"""Robustness harness: damaged and odd inputs against bagtools' promise on bad input.

- ``corpus.py``: ``build_corpus(dest, "small"|"full")`` writes damaged MCAP / sqlite3 / ROS 1
  bags, lying metadata, damaged messages (scans, clouds, tf, odometry), bad option values,
  TUM files, impossible output paths and data-loss setups, each with its expected outcome;
  ``scene.py`` (the synthetic recording it damages) and ``damage.py`` (byte-level edits).
- ``runner.py``: ``run_case(argv, out_dir, timeout_s, mem_limit_bytes)`` runs one command
  in a forked child with an address-space limit and classifies the outcome; ``judge``.
- ``test_corpus.py``: the small corpus as pytest cases (about a minute).
- ``test_properties.py``: hypothesis properties of the decoders, TfBuffer and the TUM reader.
- ``hostile.py``: ``python -m tests.robustness.hostile [--full] [-j 2]``, a table of failures.
"""
