"""Names the user chooses between, defined once for the library and the command line.

Plain tuples with no imports, so that ``whiskerid --help`` can list them without starting JAX.
"""

#: What a recording measures (``simulate`` writes, ``calibrate`` fits).
OBSERVABLES = ("deflection", "acceleration", "voltage", "adc")
#: How the whisker was excited.
EXCITATIONS = ("decay", "sine", "base")
#: Response models of ``simulate``: the paper's Eq. 1, the harmonic steady state, the exact
#: response from rest.
MODELS = ("paper", "steady", "exact")
#: Units of each observable, written into recordings.
UNITS = {"deflection": "m", "acceleration": "m/s^2", "voltage": "V", "adc": "code"}
#: What fixes EI or C when vibration data alone cannot.
PINS = ("auto", "geometry", "material")
#: Least-squares solvers (optimistix).
SOLVERS = ("levenberg-marquardt", "dogleg", "gauss-newton")
#: Noise models of the posterior.
LIKELIHOODS = ("gaussian", "student")
#: emcee moves.
MOVES = ("de", "stretch", "de-snooker")
#: Feature sets of the classifier.
FEATURE_KINDS = ("fitted", "paper")
#: Terrains of the simulator and of the paper's dataset.
TERRAINS = ("flat", "cement", "brick", "carpet", "soft-grass", "sand", "soft-soil")
#: Nominal robot speeds of the paper's dataset (m/s).
SPEEDS_MPS = (0.10, 0.15, 0.20, 0.25, 0.30)
