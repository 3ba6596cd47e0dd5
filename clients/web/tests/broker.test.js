// brokerParams: the page's query string -> the broker, subject and viewer login (src/broker.js).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { brokerParams } from '../src/broker.js';

test('no broker parameter: the page connects to performer run', () => {
  assert.equal(brokerParams('?ws=ws://h:8765/ws'), null);
});

test('broker, subject (a trailing .frames accepted) and the viewer login', () => {
  assert.deepEqual(brokerParams('?broker=ws://b:8080&subject=performer.alice.frames&user=viewer&pass=v'),
    { url: 'ws://b:8080', subject: 'performer.alice', auth: { user: 'viewer', pass: 'v' } });
  assert.deepEqual(brokerParams('?broker=wss://b&token=t'),
    { url: 'wss://b', subject: 'performer.main', auth: { token: 't' } });
});
