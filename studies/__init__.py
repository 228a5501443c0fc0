"""The studies behind fastvi's documentation pages, in the source repository only.

Each module is the single source of a page and its figures: :mod:`studies.wpd` (``docs/wpd.md``,
the speed study), :mod:`studies.orders` (``docs/orders.md``), :mod:`studies.paper_b`
(``docs/paper-b.md``); :mod:`studies.peers` holds the compiled peers of the speed study
(CyRK, the ``bench`` extra). They run from the repository root as ``python -m fastvi wpd``
(or ``python -m studies.wpd``), ``make wpd``, ``make orders``, ``make paper-b``. They are not
installed with fastvi (docs/decisions/0011-studies-in-the-package.md); what is, is
:mod:`fastvi.studies`: the demo and the reference solutions and order fits it uses.
"""
