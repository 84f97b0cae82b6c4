"""Helpers shared by the component tests (imported as a plain module, like paths)."""
import itertools


def option_combinations(cls):
    """Every combination of a component type's choice and boolean options (others at default)."""
    axes = []
    for name, opt in cls.options.items():
        if opt.choices is not None:
            axes.append([(name, c) for c in opt.choices])
        elif opt.kind is bool:
            axes.append([(name, False), (name, True)])
        else:
            axes.append([(name, opt.default)])
    return [dict(c) for c in itertools.product(*axes)]
