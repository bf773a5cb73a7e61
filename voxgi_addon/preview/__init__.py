"""The camera's preview passes (Cycles' names and meanings), reduced-resolution upsampling and the
plain-numpy layouts the GPU tracer uploads."""
