"""secure.read_config_section: a domain's section of a config file, read as every `secure`
command reads it (experiments::ReadSection): the `domain:` key, then the preset, then the rest."""
import pytest

import secure


def write(tmp_path, text):
    path = tmp_path / "config.yaml"
    path.write_text(text)
    return str(path)


def test_the_section_goes_over_the_preset_and_feeds_the_shield(tmp_path):
    # A file without the domain's section (an empty file is no mapping of sections).
    other = write(tmp_path, "bc: {epochs: 3}\n")
    preset = secure.read_config_section(other, "double-integrator", "quick")
    assert preset["section"] == "pipeline"
    path = write(tmp_path, "pipeline:\n  shield: {class_k_gain: 5, num_samples: 48}\n")
    section = secure.read_config_section(path, "double-integrator", "quick")
    shield = section["experiment"]["shield"]
    assert shield["class_k_gain"] == 5 and shield["num_samples"] == 48
    assert shield["max_iterations"] == preset["experiment"]["shield"]["max_iterations"]
    assert section["domain"] == preset["domain"]


def test_the_domain_key_comes_before_the_preset(tmp_path):
    # A file without the domain's section (an empty file is no mapping of sections).
    other = write(tmp_path, "bc: {epochs: 3}\n")
    preset = secure.read_config_section(other, "double-integrator", "quick")
    dt = preset["experiment"]["shield"]["dt"]
    path = write(tmp_path, f"pipeline:\n  domain: {{task: {{dt: {dt / 2}}}}}\n")
    section = secure.read_config_section(path, "double-integrator", "quick")
    assert section["domain"]["task"]["dt"] == pytest.approx(dt / 2)
    assert section["experiment"]["shield"]["dt"] == pytest.approx(dt / 2)


def test_errors_name_the_file_and_the_field(tmp_path):
    path = write(tmp_path, "pipeline:\n  sheild: {class_k_gain: 5}\n")
    with pytest.raises(ValueError, match=r"config.yaml \[pipeline\]: unknown section 'sheild'"):
        secure.read_config_section(path, "double-integrator")
    with pytest.raises(FileNotFoundError):
        secure.read_config_section(str(tmp_path / "missing.yaml"), "double-integrator")


def test_every_domains_options_go_back_into_make_env(tmp_path):
    # The section's 'domain' dict is what make_env takes: every key it holds is one the domain
    # reads (Derby, the double integrator and the toy plug-in used to write keys they rejected).
    other = write(tmp_path, "bc: {epochs: 3}\n")
    for name in secure.domains():
        options = secure.read_config_section(other, name, "quick")["domain"]
        secure.make_env(name, profile="quick", **options).close()
        assert secure.EnvCore(name, "quick", options=options).options == options, name
