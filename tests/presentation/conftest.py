"""Archives the explorer's tests share."""
import pytest

from survey.cli import main

BREATHING = ('[initial]\nfamily = "equilateral"\ndelta = 0.0\n\n'
             '[periodic]\nmode = 3\nparameter = "energy"\nto = 150.0\nsteps = 3\n')
ROUTH = '''
[system]
masses = [1.0, 0.01, 0.0001]
interactions = [{kind = "pair", potential = "gravity", params = {G = 1.0}}]
[initial]
family = "explicit"
positions = [[1.0, 0.0], [-0.5, 0.8660254037844386], [-0.5, -0.8660254037844386]]
[equilibria]
rotation_rate = 1.0
parameter = "mass_1"
to = 0.06
steps = 5
'''


@pytest.fixture(scope="session")
def families(tmp_path_factory):
    """A periodic family (the homographic breathing orbits in energy) and a family of
    relative equilibria (Lagrange's triangle along a mass), each as --output writes it."""
    folder = tmp_path_factory.mktemp("families")
    out = {}
    for kind, text in (("periodic", BREATHING), ("equilibria", ROUTH)):
        (folder / f"{kind}.toml").write_text(text)
        out[kind] = folder / f"{kind}.nc"
        assert main([kind, str(folder / f"{kind}.toml"), "--output", str(out[kind])]) == 0
    return out
