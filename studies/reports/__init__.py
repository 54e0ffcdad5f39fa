"""This repository's report generators: one module each, turning the committed results of its campaigns (the study
files beside this folder) into the reports under docs/results and the tables of the README and docs.
``bridgeplan study report`` imports this package from the repository root (``bridgeplan.studies.generators.load``);
the interface of a generator: ``bridgeplan/studies/generators.py``."""

from bridgeplan.studies.generators import Generator

GENERATORS = {g.name: g for g in [
    Generator("findings", "findings", "findings.md",
              "each finding per maze and task set, paired over seeds, with its verdict; the score-95 goal", ()),
    Generator("prior-curves", "prior_curves", "prior-curves.md",
              "flow matching, the I2SB and the consistent bridge from each prior across training, against DDPM", ()),
    Generator("controllers", "controllers", "controllers.md",
              "tracking against pursuit at each lookahead, open loop and replanned, per maze and task set", ()),
    Generator("wallclock", "wallclock", "throughput-wallclock.md",
              "training settings at equal minutes of training: score, success and windows/s, paired over seeds", ()),
    Generator("headline", "headline", "headline.md",
              "the best tracked and the best pursued planner per maze and task set, with the floors and the expert",
              ("README.md",)),
    Generator("ogbench-calibration", "ogbench_calibration", "ogbench-calibration.md",
              "OGBench pointmaze: the oracle and GCBC on locally generated data by OGBench's protocol, beside "
              "OGBench's published GCBC", ("docs/ogbench_pointmaze.md",)),
    Generator("manipulation", "manipulation", "manipulation.md",
              "OGBench manipulation, per play dataset: GCBC, GCIQL, planners and the dataset graph by OGBench's "
              "protocol, beside the published numbers", ("README.md",)),
    Generator("ogbench-planners", "ogbench_planners", "ogbench-planners.md",
              "OGBench pointmaze navigate: DDPM and flow by OGBench's protocol, the controller chosen on validation, "
              "beside the line alone, the oracle and the published methods", ("docs/results/README.md",)),
    Generator("hierarchy", "hierarchy", "hierarchy.md",
              "hierarchical planning on large: a coarse plan refined by a low level, beside the coarse plans alone, "
              "the best flat planner, the line and the expert", ("docs/results/README.md",)),
    Generator("cddb", "cddb", "cddb.md",
              "CDDB consistency corrections of the consistent bridge and flow against DDPM's best, chosen on "
              "validation", ("docs/results/README.md",)),
    Generator("onestep", "onestep", "onestep.md",
              "one network call (mean flows, shortcut models, DDPM distilled) at NFE 1 and 2 against DDPM's best at "
              "any NFE, per maze, execution and task set, paired over seeds", ()),
    Generator("demo", "demo", "demo.md",
              "what `bridgeplan demo` prints at seeds 0, 1 and 2: the README's expected range", ("README.md",)),
    Generator("gpu", "gpu", "gpu.md",
              "the bench on a GPU beside the same figures on the CPU, and a short real run trained and evaluated there",
              ("README.md",)),
    Generator("shipped", "shipped", "shipped.md",
              "the shipped planners (one training run each of the headline's method): their files and their own "
              "scores at the headline's settings, beside the headline's", ("README.md",)),
]}
