// Records of the selected device: its recorder (the controller's, writing MCAP on the device:
// SendCommand "recorder start", "recorder stop", "recorder store"), and downloads of what the
// device keeps: the stored recording (RecordingService.FetchRecording, an operator's; checked
// against the SHA-256 its last chunk carries) and the audit log (AuditService.ReadAuditLog,
// an admin's: it names people; the download is itself audited). Both stream chunks of bytes,
// which the page puts together into one file the browser saves.
const $ = (id) => document.getElementById(id);
const FETCH_RECORDING = 'landscape.v1.RecordingService/FetchRecording';
const READ_AUDIT_LOG = 'landscape.v1.AuditService/ReadAuditLog';

// protobuf's JSON gives bytes as base64.
function bytesOf(base64) {
  const text = atob(base64 || '');
  const bytes = new Uint8Array(text.length);
  for (let i = 0; i < text.length; i += 1) bytes[i] = text.charCodeAt(i);
  return bytes;
}

async function sha256Hex(blob) {
  const digest = await crypto.subtle.digest('SHA-256', await blob.arrayBuffer());
  return [...new Uint8Array(digest)].map((b) => b.toString(16).padStart(2, '0')).join('');
}

function save(blob, fileName) {
  const url = URL.createObjectURL(blob);
  const link = document.createElement('a');
  link.href = url;
  link.download = fileName;
  document.body.append(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(url), 60_000);
}

export class RecordsPanel {
  constructor(selection) {
    this.selection = selection;
    for (const action of ['start', 'stop', 'store']) {
      $(`btn-recorder-${action}`).addEventListener('click', async () => {
        const reply = await selection.ctx.command('SendCommand', { input: `recorder ${action}` });
        if (reply) $('recorder-result').textContent = `${selection.device.name}: ${reply.result}`;
      });
    }
    $('btn-download-recording').addEventListener('click', () => this.recording());
    $('btn-download-audit').addEventListener('click', () => this.auditLog());
    selection.on((what) => {
      if (what === 'switch') $('recorder-result').textContent = $('download-result').textContent = '';
    });
  }

  // Every reply of a stream of the selected device, or null once its refusal is shown.
  async collect(rpc, request) {
    const { ctx } = this.selection;
    try {
      return await ctx.link.collect(ctx.device, rpc, request);
    } catch (error) {
      if (!error.status) throw error;
      ctx.refused(rpc.split('/').pop(), error.status);
      return null;
    }
  }

  async recording() {
    const device = this.selection.device.name;
    const chunks = await this.collect(FETCH_RECORDING, { offset: '0' });
    if (!chunks?.length) return;
    const [first] = chunks;
    const blob = new Blob(chunks.map((c) => bytesOf(c.data)), { type: first.mediaType });
    const expected = chunks[chunks.length - 1].sha256;
    if (expected && await sha256Hex(blob) !== expected) {
      $('download-result').textContent = `${device}: ${first.name} arrived damaged (its SHA-256 differs); not saved`;
      return;
    }
    save(blob, `${device}-${first.name}`);
    $('download-result').textContent = `${device}: ${first.name}, ${blob.size} bytes, saved`;
  }

  async auditLog() {
    const device = this.selection.device.name;
    const chunks = await this.collect(READ_AUDIT_LOG, {});
    if (!chunks) return;
    const blob = new Blob(chunks.map((c) => bytesOf(c.records)), { type: 'application/x-ndjson' });
    save(blob, `${device}-audit.jsonl`);
    const files = new Set(chunks.map((c) => c.file));
    $('download-result').textContent = `${device}: the audit log (${[...files].join(', ') || 'empty'}), ${blob.size} bytes, saved`;
  }
}
