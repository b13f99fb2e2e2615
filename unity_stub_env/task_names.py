"""The stub's task names without importing the tasks (MuJoCo takes ~0.4 s to import), so the
trainer can refuse ``--env stub:NAME`` for an unknown NAME before it creates anything.
tests/stub keeps this in step with ``unity_stub_env.tasks.TASKS``."""

TASK_NAMES = ("ball3d", "basic", "dodge", "creature", "mimic", "runner", "soccer", "soccer_twos", "pushblock",
              "dungeon")

# ``mirror`` replays a behaviors.json (``--task mirror=FILE``); not in TASK_NAMES: it needs a file
MIRROR_TASK = "mirror"
