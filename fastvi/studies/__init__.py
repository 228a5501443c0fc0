"""The demo (``python -m fastvi demo``) and the helpers it shares with the tests and the
repository's studies: independent reference solutions (:mod:`.reference`), observed orders
(:mod:`.convergence`) and the commands' argument parsers (:mod:`.cli`).

The studies that regenerate the documentation pages live in the source repository's
``studies/`` folder, not in the installed package.
"""
