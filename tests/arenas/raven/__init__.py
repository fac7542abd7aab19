FAST_COMPILE = {"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True,
                "xla_cpu_use_fusion_emitters": False}
"""XLA's quick compile options: the Raven tests compile MJX programs whose behaviour does not depend on them."""
