"""The codec flatc 2.0.8 generates from proto/tactile.fbs (flatc --python --gen-object-api),
imports moved from tactile.proto to tactile_proto.generated. Do not edit: run proto/python/generate.py."""
