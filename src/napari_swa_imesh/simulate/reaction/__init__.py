"""The command line of the reaction-diffusion runs (``simulate --model fisher-kpp|drug``);
the library is :func:`napari_swa_imesh.simulate.simulate_growth`."""
