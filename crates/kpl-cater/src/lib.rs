//! LA-CATER formats, a CATER-style generator, OPNet-style scoring and snitch localisation models.
