"""`python -m saim_mesh.tak SCENARIO --connect ... --cot-url ...` (see gateway.main)."""
import sys

from .gateway import main

sys.exit(main())
