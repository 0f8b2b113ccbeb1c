"""What the diagnostics share: a domain's config section read as every `secure` command reads it."""
import tempfile

import secure


def read_section(domain, config=None):
    """secure.read_config_section of `config`, or of an empty file (the domain's preset)."""
    if config:
        return secure.read_config_section(config, domain)
    with tempfile.NamedTemporaryFile("w", suffix=".yaml") as empty:
        empty.write("{}\n")
        empty.flush()
        return secure.read_config_section(empty.name, domain)
