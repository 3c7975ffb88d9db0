# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""An SROS2 keystore in rcl's layout, made with the ``cryptography`` package (no sros2: it is not on
PyPI), for processes that run with DDS Security (``ROS_SECURITY_ENABLE=true``).

The layout is what ``ros2 security create_keystore`` and ``create_enclave`` make, and what rcl
and rmw_fastrtps read (rcl's ``rcl_get_secure_root``: ``<keystore>/enclaves/<enclave>``;
rmw_dds_common's security files)::

    <root>/public/ca.cert.pem            one CA, the identity CA and the permissions CA
    <root>/private/ca.key.pem
    <root>/enclaves/governance.xml, governance.p7s
    <root>/enclaves/<enclave>/identity_ca.cert.pem, permissions_ca.cert.pem (the CA)
                              governance.p7s, cert.pem, key.pem, permissions.xml, permissions.p7s

The governance protects discovery, liveliness, whole RTPS messages (``rtps_protection_kind``) and
each submessage (``metadata_protection_kind``) at one kind, ``ENCRYPT`` or ``SIGN``, and each
payload (``data_protection_kind``) at that kind or another (``NONE`` too); joining needs a
certificate of the CA, and every topic's reads and writes are access-controlled. An enclave's
permissions allow every topic on every domain, but those matching its ``deny`` expressions
(DDS-Security's fnmatch patterns, e.g. ``*/cft_action_x/_action/*``), whose rule comes first.
Certificates and signatures as sros2 makes
them: prime256v1 keys, SHA-256, S/MIME with a detached signature over the text.
"""

from __future__ import annotations

import datetime
import os
from pathlib import Path
from typing import Optional, Sequence

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.hazmat.primitives.serialization import pkcs7
from cryptography.x509.oid import NameOID

#: The protection kinds a governance can be made with (the whole message, submessages, payloads).
PROTECTIONS = ('ENCRYPT', 'SIGN')
#: ... and those of its payloads.
PAYLOAD_PROTECTIONS = (*PROTECTIONS, 'NONE')
#: Every ROS domain (rcl's ROS_DOMAIN_ID is 0..232 on UDP).
_DOMAINS = '<domains><id_range><min>0</min><max>232</max></id_range></domains>'
_XSI = 'xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"'
_VALID_DAYS = 30


def _governance(protection: str, payload: str) -> str:
    return f'''<?xml version="1.0" encoding="UTF-8"?>
<dds {_XSI}>
  <domain_access_rules>
    <domain_rule>
      {_DOMAINS}
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>{protection}</discovery_protection_kind>
      <liveliness_protection_kind>{protection}</liveliness_protection_kind>
      <rtps_protection_kind>{protection}</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>{protection}</metadata_protection_kind>
          <data_protection_kind>{payload}</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
'''


def _permissions(enclave: str, deny: Sequence[str], now: datetime.datetime) -> str:
    def topics(expressions: Sequence[str]) -> str:
        return '<topics>' + ''.join(f'<topic>{e}</topic>' for e in expressions) + '</topics>'

    def rule(kind: str, expressions: Sequence[str]) -> str:
        return (f'<{kind}>{_DOMAINS}<publish>{topics(expressions)}</publish>'
                f'<subscribe>{topics(expressions)}</subscribe></{kind}>')

    def stamp(when: datetime.datetime) -> str:
        return when.strftime('%Y-%m-%dT%H:%M:%S')

    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<dds {_XSI}><permissions>'
            f'<grant name="{enclave}"><subject_name>CN={enclave}</subject_name>'
            f'<validity><not_before>{stamp(now - datetime.timedelta(days=1))}</not_before>'
            f'<not_after>{stamp(now + datetime.timedelta(days=_VALID_DAYS))}</not_after></validity>'
            + (rule('deny_rule', deny) if deny else '') + rule('allow_rule', ['*'])
            + '<default>DENY</default></grant></permissions></dds>\n')


class Keystore:
    """A keystore under ``root`` with one CA and a governance of ``protection`` (one of
    :data:`PROTECTIONS`), its payloads' ``payload`` (one of :data:`PAYLOAD_PROTECTIONS`, by
    default ``protection``); :meth:`enclave` adds an enclave and gives a process's environment."""

    def __init__(self, root: Path, protection: str, payload: Optional[str] = None) -> None:
        payload = payload or protection
        if protection not in PROTECTIONS or payload not in PAYLOAD_PROTECTIONS:
            raise ValueError(f'protection {protection!r}, payloads {payload!r}: not one of '
                             f'{PROTECTIONS}, {PAYLOAD_PROTECTIONS}')
        self.root, self.protection, self.payload = root, protection, payload
        self._now = datetime.datetime.now(datetime.timezone.utc)
        name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, 'cft_action test CA')])
        self._ca_key = ec.generate_private_key(ec.SECP256R1())
        self._ca = self._certificate(name, name, self._ca_key.public_key(), ca=True)
        self._write(root / 'public' / 'ca.cert.pem',
                    self._ca.public_bytes(serialization.Encoding.PEM))
        self._write(root / 'private' / 'ca.key.pem', self._pem(self._ca_key))
        governance = _governance(protection, payload).encode()
        self._write(root / 'enclaves' / 'governance.xml', governance)
        self._write(root / 'enclaves' / 'governance.p7s', self._signed(governance))

    def enclave(self, name: str, deny: Sequence[str] = ()) -> dict[str, str]:
        """Make the enclave ``name`` (``/cft/server``), its permissions denying the topics that
        match ``deny``; return the environment that runs a ROS process in it, Enforce."""
        folder = self.root / 'enclaves' / name.lstrip('/')
        folder.mkdir(parents=True)
        for link, target in (('identity_ca.cert.pem', 'public/ca.cert.pem'),
                             ('permissions_ca.cert.pem', 'public/ca.cert.pem'),
                             ('governance.p7s', 'enclaves/governance.p7s')):
            os.symlink(os.path.relpath(self.root / target, folder), folder / link)
        key = ec.generate_private_key(ec.SECP256R1())
        subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
        certificate = self._certificate(subject, self._ca.subject, key.public_key(), ca=False)
        self._write(folder / 'cert.pem', certificate.public_bytes(serialization.Encoding.PEM))
        self._write(folder / 'key.pem', self._pem(key))
        permissions = _permissions(name, deny, self._now).encode()
        self._write(folder / 'permissions.xml', permissions)
        self._write(folder / 'permissions.p7s', self._signed(permissions))
        return {'ROS_SECURITY_KEYSTORE': str(self.root), 'ROS_SECURITY_ENABLE': 'true',
                'ROS_SECURITY_STRATEGY': 'Enforce', 'ROS_SECURITY_ENCLAVE_OVERRIDE': name}

    def _certificate(self, subject: x509.Name, issuer: x509.Name,
                     public_key: ec.EllipticCurvePublicKey, *, ca: bool) -> x509.Certificate:
        """A certificate of ``subject``'s ``public_key``, signed by the CA's key."""
        return (x509.CertificateBuilder()
                .issuer_name(issuer)
                .subject_name(subject)
                .serial_number(x509.random_serial_number())
                .not_valid_before(self._now - datetime.timedelta(days=1))
                .not_valid_after(self._now + datetime.timedelta(days=_VALID_DAYS))
                .public_key(public_key)
                .add_extension(x509.BasicConstraints(ca=ca, path_length=1 if ca else None),
                               critical=ca)
                .sign(self._ca_key, hashes.SHA256()))

    def _signed(self, document: bytes) -> bytes:
        """``document`` as S/MIME, signed by the CA (detached, over the text), as sros2 signs."""
        return (pkcs7.PKCS7SignatureBuilder().set_data(document)
                .add_signer(self._ca, self._ca_key, hashes.SHA256())
                .sign(serialization.Encoding.SMIME,
                      [pkcs7.PKCS7Options.Text, pkcs7.PKCS7Options.DetachedSignature]))

    @staticmethod
    def _pem(key: ec.EllipticCurvePrivateKey) -> bytes:
        return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                 serialization.NoEncryption())

    @staticmethod
    def _write(path: Path, content: bytes) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(content)
