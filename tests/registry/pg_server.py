"""A real PostgreSQL server for the registry's tests, started in a temporary directory and
reached on a Unix socket only (no TCP port): initdb and pg_ctl from Debian's postgresql package.
PostgreSQL refuses to run as root, so under root (CI) the server runs as nobody."""
import glob
import os
import shutil
import socket
import subprocess


def find_bin(name):
    """initdb/pg_ctl/psql: on PATH, else Debian's /usr/lib/postgresql/VERSION/bin."""
    found = shutil.which(name)
    if found and name == "psql":
        return found
    candidates = sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"), reverse=True)
    if candidates:
        return candidates[0]
    return found


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def available():
    return all(find_bin(n) for n in ("initdb", "pg_ctl", "psql"))


class PgServer:
    def __init__(self, base_dir, port=None, fsync=False, tls=False):
        self.base = os.path.abspath(base_dir)
        self.data = os.path.join(self.base, "pgdata")
        self.sock = os.path.join(self.base, "pgsock")
        self.log = os.path.join(self.base, "pg.log")
        self.port = port or free_port()
        # TLS on 127.0.0.1 (a self-signed certificate for "localhost") besides the Unix socket.
        self.tls = tls
        self.ca = os.path.join(self.base, "server.crt")
        self.as_nobody = os.geteuid() == 0
        self.fsync = fsync  # off in tests (speed); on for the benchmark, as a real server runs

    def _run(self, argv, **kw):
        if self.as_nobody:
            argv = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", *argv]
        return subprocess.run(argv, capture_output=True, text=True, **kw)

    def init(self, password=None):
        """A new cluster with the superuser turncal: trust, or scram-sha-256 with `password`."""
        os.makedirs(self.sock, exist_ok=True)
        os.chmod(self.base, 0o755)
        if self.as_nobody:
            # The server's user must reach its directory: the test's (mkdtemp, 0700) is opened
            # for traversal only.
            parent = os.path.dirname(self.base)
            os.chmod(parent, os.stat(parent).st_mode | 0o711)
        if self.as_nobody:
            os.chown(self.sock, 65534, 65534)
            os.makedirs(self.data, exist_ok=True)
            os.chown(self.data, 65534, 65534)
            open(self.log, "a").close()
            os.chown(self.log, 65534, 65534)
        auth = ["--auth=trust"]
        if password:
            pwfile = os.path.join(self.base, "pwfile")
            with open(pwfile, "w") as f:
                f.write(password + "\n")
            if self.as_nobody:
                os.chown(pwfile, 65534, 65534)
            auth = ["--auth=scram-sha-256", f"--pwfile={pwfile}"]
        r = self._run([find_bin("initdb"), "-D", self.data, "-U", "turncal", *auth,
                       "--no-sync", "-E", "UTF8", "--locale=C"])
        if r.returncode != 0:
            raise RuntimeError("initdb failed: " + r.stdout + r.stderr)
        if self.tls:
            key = os.path.join(self.base, "server.key")
            r = subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes",
                                "-keyout", key, "-out", self.ca, "-days", "2", "-subj",
                                "/CN=localhost", "-addext",
                                "subjectAltName=DNS:localhost,IP:127.0.0.1"],
                               capture_output=True, text=True)
            if r.returncode != 0:
                raise RuntimeError("openssl req failed: " + r.stderr)
            os.chmod(key, 0o600)
            if self.as_nobody:
                os.chown(key, 65534, 65534)
        if password:
            os.environ["PGPASSWORD"] = password  # psql's (the checks'), and turncal's CLI
        self.start()
        self.psql("CREATE DATABASE turncal", db="postgres")

    def start(self):
        options = (f"-k {self.sock} -p {self.port} -c fsync={'on' if self.fsync else 'off'} " +
                   (f"-c listen_addresses=127.0.0.1 -c ssl=on -c ssl_cert_file={self.ca} "
                    f"-c ssl_key_file={os.path.join(self.base, 'server.key')}" if self.tls
                    else "-c listen_addresses=''"))
        r = self._run([find_bin("pg_ctl"), "-D", self.data, "-l", self.log, "-w", "-t", "120",
                       "-o", options, "start"])
        if r.returncode != 0:
            raise RuntimeError("pg_ctl start failed: " + r.stdout + r.stderr +
                               open(self.log).read()[-2000:])

    def stop(self, mode="fast"):
        self._run([find_bin("pg_ctl"), "-D", self.data, "-m", mode, "-w", "-t", "120", "stop"])

    def conninfo(self, db="turncal"):
        return f"host={self.sock} port={self.port} dbname={db} user=turncal"

    def tls_conninfo(self, db="turncal"):
        """Over TCP with TLS, the server's certificate and name checked (verify-full)."""
        return (f"host=localhost hostaddr=127.0.0.1 port={self.port} dbname={db} user=turncal "
                f"sslmode=verify-full sslrootcert={self.ca}")

    def psql(self, sql, db="turncal"):
        """The query's rows as lists of strings (unaligned, tab-separated)."""
        r = subprocess.run([find_bin("psql"), "-X", "-A", "-t", "-F", "\t", "-v",
                            "ON_ERROR_STOP=1", "-d", self.conninfo(db), "-c", sql],
                           capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"psql {sql!r}: {r.stderr}")
        return [line.split("\t") for line in r.stdout.splitlines() if line]
