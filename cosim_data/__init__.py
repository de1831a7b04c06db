"""Data sets shipped with the package for its tools, outside the FMU packages (an FMU bundles
the data files of the packages it imports; these are none of them): ``ttobench/``, TTOBench's
track, train and journey instances (its README.md: source, licence, citation)."""
