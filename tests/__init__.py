"""The test suite, laid out like the package (docs/testing.md, "Layout").

core/, components/, fmu/, studies/, hil/, front/   the tests of each layer of reeve_fmu
oracles/        the engine against closed-form physics (static elongation, beta tan beta, energy balance,
                damped oscillators, the crane block's rotation)
architecture/   rules of the code and of the suite (layers, function length, the bound checks)
support/        what the tests share: the bound checks (checks.py), the jobs the tests run in fresh
                interpreters (*_jobs.py), the C host, the toy FMU, helpers; imported as tests.support
scenes/         scene files only the tests use
"""
