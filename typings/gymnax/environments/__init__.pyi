# an optional extra ([rl], [cluster]): the type check runs without it, so it is Any there
from typing import Any

def __getattr__(name: str) -> Any: ...
