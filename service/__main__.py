"""``python -m service``: the same as ``tracker-service``."""

from __future__ import annotations

import sys

from service.main import main

if __name__ == "__main__":
    sys.exit(main())
