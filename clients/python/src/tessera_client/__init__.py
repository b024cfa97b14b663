"""Python client of the Tessera render farm.

    from tessera_client import Client
    c = Client("http://127.0.0.1:7878", token="...")
    job = c.submit("scene.xml", integrator="pt", spp=64, seed=1)
    job.wait(timeout=600, progress=lambda j: print(j["state"], j["progress"]))
    job.download("out.exr")      # and out.png beside it
"""

from .bundle import BundleError, pack, referenced_files
from .client import Client, Job, JobFailed, TesseraError
from .events import Event

__all__ = ["BundleError", "Client", "Event", "Job", "JobFailed", "TesseraError", "pack", "referenced_files"]
__version__ = "0.1.0"
