// Records of the selected device: its recorder (the controller's, writing MCAP on the device:
// SendCommand "recorder start", "recorder stop", "recorder store"), and the downloads of a
// recording and of the audit log, which the contract does not offer yet: their buttons say so
// and stay disabled (docs/page.md says what the contract needs).
const $ = (id) => document.getElementById(id);

export class RecordsPanel {
  constructor(selection) {
    for (const action of ['start', 'stop', 'store']) {
      $(`btn-recorder-${action}`).addEventListener('click', async () => {
        const reply = await selection.ctx.command('SendCommand', { input: `recorder ${action}` });
        if (reply) $('recorder-result').textContent = `${selection.device.name}: ${reply.result}`;
      });
    }
    selection.on((what) => { if (what === 'switch') $('recorder-result').textContent = ''; });
  }
}
