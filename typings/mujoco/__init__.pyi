# mujoco's names come from compiled modules that pyright cannot read and it ships no stubs:
# everything in it is Any to the type checker (.ci/typecheck).
from typing import Any

def __getattr__(name: str) -> Any: ...
