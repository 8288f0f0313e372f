"""Engine adapters written with the realitygap_engine SDK, one module each (``python -m realitygap_engine.adapters.NAME``)."""
