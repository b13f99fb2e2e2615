"""The end-to-end helpers and fixtures of tests/integration serve the learning tests too."""
from tests.integration.conftest import basic_config, env_no_proxy  # noqa: F401
