import sys
from pathlib import Path

# The benchmark package lives at the repository root (bench/compare), next to core/.
ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
