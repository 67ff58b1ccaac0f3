# SPDX-License-Identifier: GPL-3.0-or-later
"""``python -m fiberform`` is the same as the ``fiberform`` command."""

from .cli import main

raise SystemExit(main())
