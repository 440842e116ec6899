"""The NBRDF network (Sztrajman et al. 2021) in one place, for every part that needs it.

`network`: the weights layout, the input encodings, the torch forward pass and `Network`
(weights + encoding + units); `keras_h5`: the published release's Keras `.h5` files;
`formats`: every weight format to and from a `Network` (`brdfbench convert`). The dataset
`nbrdf_release`, the `nbrdf` / `naive_mlp` representations and their drjit kernel all use
these, so the network is defined once. Importing this package imports nothing heavy.
"""
