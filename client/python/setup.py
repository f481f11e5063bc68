"""Build step of the radiosity package (pyproject.toml): the messages and stubs of
radiosity.v1 generated from the repository's proto/ with protoc and grpc_python_plugin."""
import os
import shutil
import subprocess

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = os.path.dirname(os.path.abspath(__file__))
PROTO = os.path.normpath(os.path.join(HERE, "..", "..", "proto"))
FILES = ["radiosity/v1/service.proto", "radiosity/v1/scene.proto"]


def tool(name):
    path = shutil.which(name)
    if path is None:
        raise SystemExit(f"radiosity: {name} is not installed (deploy/packages.txt lists the "
                         "Debian package that has it: protobuf-compiler, protobuf-compiler-grpc)")
    return path


class BuildWithStubs(build_py):
    def run(self):
        super().run()
        out = os.path.join(self.build_lib)
        os.makedirs(os.path.join(out, "radiosity", "v1"), exist_ok=True)
        if not os.path.isfile(os.path.join(PROTO, FILES[0])):
            raise SystemExit(f"radiosity: {PROTO}/{FILES[0]} not found: build the package from "
                             "the repository (pip install ./client/python)")
        subprocess.run([tool("protoc"), f"-I{PROTO}", "-I/usr/include", f"--python_out={out}",
                        f"--grpc_python_out={out}",
                        f"--plugin=protoc-gen-grpc_python={tool('grpc_python_plugin')}"] + FILES,
                       check=True)
        open(os.path.join(out, "radiosity", "v1", "__init__.py"), "a").close()


setup(cmdclass={"build_py": BuildWithStubs})
